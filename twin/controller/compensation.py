"""Reference compensations: the offsets a CNC adds to the interpolated reference so that the
table, not the motor, follows the path (``[controller.compensation]``, issue 31).

They come from the controller's belief only (its axes, its loop model, its shapers), never
from the plant. The offset of axis k is::

    Δ_k = (m_k/k_k − c_k)·a_n,k          on the raw reference, before the input shapers
        + D_k·r_k + β_k·v_k              on the shaped reference, after them

* ``a_n`` is the reference's normal acceleration, the part of a perpendicular to v
  (v²κ on a curve; 0 on a straight line, so corners and the moves along a line keep their
  points).
* **Smoothing** (``smoothing``): a filter of unit DC gain with impulse response of variance
  σ² turns x(t) into x(t − τ) + (σ²/2)·x''(t − τ) + …, so a curve run at centripetal
  acceleration a_n shrinks by a_n·σ²/2. The shapers (σ_s² of their taps) and the closed
  position loop on the controller's linear model (σ_L², ``loop_variance``) both do this;
  ``c`` = (σ_s² + σ_L²)/2 and the shaped, followed curve keeps its radius to O(Ω⁴σ⁴)
  (``compensated_circle_error``, ``smoothing_quartic``). The shaper still cancels the
  mode: it acts on any input. Where the curvature steps at speed the first impulse meets
  the offset before the others (``curvature_step_error``): the planner bounds that step.
* **Stretch** (``stretch``): a transmission of stiffness k pulling the moving mass m against
  viscous friction b and Coulomb friction F_c stretches by (m·a + b·v + F_c·sign v)/k,
  which a motor-side encoder does not see. m/k acts on a_n (the curve's quasi-static
  stretch, outward), β = b/k, and D = F_c/k: where an axis reverses, the friction's stretch
  flips by 2D (the quadrant glitch). The friction's side r (``compensate_reference``)
  flips with the shaped velocity across ``|v| < v_0 = reversal_band`` and holds while the
  axis stops: the reversal compensation of Siemens' and Heidenhain's controls.

The velocity channel gets the offsets' backward difference over the period (the
acceleration and jerk channels are left: a step of the offset has no finite derivative),
so a velocity feed-forward follows the offset too. ``compensate_reference`` is the one
implementation: the Python tick and the compiled tick both call it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numba
import numpy as np

from twin.config import AXES, AxisConfig, moving_masses
from twin.controller.dcu import error_coefficients
from twin.controller.gains import RegulatorGains
from twin.controller.linear import LinearAxisModel
from twin.controller.shaping import InputShaper

__all__ = ["NO_COMPENSATION", "ReferenceCompensation", "compensate_reference",
           "compensated_circle_error", "compensation_table", "curvature_step_error",
           "curve_quartic", "curve_step_acceleration", "loop_variance",
           "smoothing_quartic"]

# columns of the parameter table
C_CURVE, C_INERTIA, C_COULOMB, C_VISCOUS, C_BAND = range(5)


def loop_variance(model: LinearAxisModel, gains: RegulatorGains, period: float,
                  axis: int) -> float:
    """The variance σ_L² (s²) of the closed position loop's impulse response, reference →
    motor position, from its error coefficients (``dcu.error_coefficients``).

    With ``e = Σ c_k ∇^k x_ref`` and ``∇ = 1 − e^(−sT) = sT − (sT)²/2 + …`` the loop is
    ``1 − m1·s + (m2/2)·s² + …`` with ``m1 = c1·T`` and ``m2/2 = (c1/2 − c2)·T²``;
    σ_L² = m2 − m1² (a first-order lag of time constant τ: τ²; negative for a loop whose
    feed-forward overshoots). A circle run at Ω shrinks by R·Ω²σ_L²/2 = a_n·σ_L²/2.
    FF1…FF3 enter as the DCU they equal (``dcu.dcu_as_feedforward`` inverted).
    """
    def pick(value):
        return value[axis] if isinstance(value, tuple) else value

    alpha = np.asarray(gains.dcu_alpha, dtype=float)
    alpha = alpha[axis] if alpha.ndim == 2 else alpha
    t = float(period)
    ff1, ff2, ff3 = pick(gains.ff1), pick(gains.ff2), pick(gains.ff3)
    a1 = ff1 / t
    a2 = ff2 / t**2 + 0.5 * a1
    a3 = ff3 / t**3 - a1 / 6.0 + a2
    c = error_coefficients(model, t, alpha + np.array([a1, a2, a3]), kp=pick(gains.kp),
                           ki=pick(gains.ki), kd=pick(gains.kd), count=3)
    m1 = c[1] * t
    m2 = 2.0 * (0.5 * c[1] - c[2]) * t * t
    return m2 - m1 * m1


def compensation_table(settings, axes: Mapping[str, AxisConfig],
                       shapers: Sequence[InputShaper | None], loop: Sequence[float],
                       period: float) -> np.ndarray:
    """``compensate_reference``'s parameters, (2, 5) per axis: c (s²), m/k (s²), D (m),
    β (s), v_0 (m/s); shape (0, 5) when both compensations are off.

    Parameters
    ----------
    settings : CompensationSettings
        Which compensations, and the reversal band.
    axes : mapping of "x", "y" to AxisConfig
        The axes as the controller believes them (mass, stiffness, friction).
    shapers : sequence of 2 InputShaper or None
        The input shapers of x and y.
    loop : sequence of 2 float
        Each axis' closed-loop variance σ_L² (s², ``loop_variance``).
    period : float
        Controller period (s): the shapers' σ² is that of their taps
        (``InputShaper.discrete``), the filter the reference really goes through.
    """
    if not (settings.smoothing or settings.stretch):
        return np.zeros((0, 5))
    out = np.zeros((2, 5))
    masses = moving_masses(axes)
    for k, name in enumerate(AXES):
        if settings.smoothing:
            shaper = shapers[k]
            spread = shaper.discrete(period).spread if shaper is not None else 0.0
            out[k, C_CURVE] += 0.5 * (spread * spread + loop[k])
        if settings.stretch:
            stiffness = axes[name].transmission.axial_stiffness
            mech = axes[name].mechanics
            out[k, C_INERTIA] = masses[name] / stiffness
            out[k, C_COULOMB] = mech.slide_coulomb / stiffness
            out[k, C_VISCOUS] = mech.slide_viscous / stiffness
        out[k, C_BAND] = settings.reversal_band
    return out


def smoothing_quartic(shaper: InputShaper) -> float:
    """g4 (s⁴): a circle through ``shaper`` and the smoothing compensation shrinks by
    ``R·g4·Ω⁴`` to fourth order, g4 = m2²/4 − m4/24 (m_k the impulses' central moments)."""
    t, a = np.asarray(shaper.times), np.asarray(shaper.amplitudes)
    d = t - shaper.lag
    m2, m4 = float(np.dot(a, d**2)), float(np.dot(a, d**4))
    return 0.25 * m2 * m2 - m4 / 24.0


def compensated_circle_error(shaper: InputShaper, radius: float, speed: float) -> float:
    """How much a circle of ``radius`` (m) at ``speed`` (m/s) shrinks through ``shaper``
    after the smoothing compensation: ``R·(1 − |H(Ω)|·(1 + Ω²σ²/2))`` (m), exactly (the
    reference's own error; compare ``shaping.circle_error``)."""
    omega = speed / radius
    h = np.sum(np.asarray(shaper.amplitudes) * np.exp(-1j * omega * np.asarray(shaper.times)))
    return float(radius * (1.0 - abs(h) * (1.0 + 0.5 * (omega * shaper.spread) ** 2)))


# --------------------------------------------------------------------------- the offset
@numba.njit(cache=True)
def compensate_reference(par, state, period, stage, ref_p, ref_v, ref_a, ref_j):
    """One tick's offsets (module docstring), added in place to the reference of both axes:
    position, and velocity by the offset's backward difference.

    ``stage`` 0, on the raw reference before the shapers: the curve term −c·a_n (the
    shapers must see it to undo their own shrink) and the inertia's stretch (m/k)·a_n (the
    shapers turn it into that of the shaped acceleration, which the table follows; the
    tangential part only moves points along a line, and leading the motor by it made the
    nest's vibration and contour worse: the loop cannot follow its steps).

    ``stage`` 1, on the shaped reference: the friction terms D·r + β·v of the shaped
    velocity, so that the offset flips where the shaped reference, which the table
    follows, reverses: a friction force that flips with the motion is met by the offset's
    step, not by a shaped staircase (the step excites no mode: it balances the friction's
    own). The friction's side r follows clip(v/v_0, −1, 1) while the speed grows, holds
    while the axis slows down and stands (a table that stops sticks with its belt
    stretched: an offset that went back to zero with v left it short by up to F_c/k), and
    where v changes sign it runs from its held value to the other side across the band.

    ``par`` (2, 5) from ``compensation_table``, shape (0, 5): nothing; ``state`` (2, 5):
    per stage the last offset and whether there is one, and the friction's side r.
    """
    if par.shape[0] == 0:
        return
    anx = any_ = 0.0
    if stage == 0:
        vx, vy = ref_v[0], ref_v[1]
        speed2 = vx * vx + vy * vy
        if speed2 > 0.0:
            along = (ref_a[0] * vx + ref_a[1] * vy) / speed2
            anx, any_ = ref_a[0] - along * vx, ref_a[1] - along * vy
    col = 2 * stage
    for k in range(2):
        if stage == 0:
            off = (par[k, C_INERTIA] - par[k, C_CURVE]) * (anx if k == 0 else any_)
        else:
            v = ref_v[k]
            u = v / par[k, C_BAND]
            if u > 1.0:
                u = 1.0
            elif u < -1.0:
                u = -1.0
            q = state[k, 4]
            if u * q < 0.0:             # reversing: from q to the new side across the band
                r = q + u * (1.0 + abs(q))
            elif u == 0.0 or abs(u) < abs(q):
                r = q                   # slowing down or at rest: the table sticks stretched
            else:
                r = u
            state[k, 4] = r
            off = par[k, C_COULOMB] * r + par[k, C_VISCOUS] * v
        dv = (off - state[k, col]) / period if state[k, col + 1] > 0.0 else 0.0
        state[k, col] = off
        state[k, col + 1] = 1.0
        ref_p[k] += off
        ref_v[k] += dv


class ReferenceCompensation:
    """The compensations of both axes over the ticks (``compensate_reference``).

    Parameters
    ----------
    par : ndarray, shape (2, 5) or (0, 5)
        ``compensation_table``.
    period : float
        Controller period (s).
    """

    def __init__(self, par: np.ndarray, period: float):
        self.par = np.ascontiguousarray(par, dtype=np.float64)
        self.period = float(period)
        self.state = np.zeros((2, 5))

    @property
    def active(self) -> bool:
        """Whether any compensation is on."""
        return self.par.shape[0] > 0

    def reset(self) -> None:
        """At rest: no offset yet."""
        self.state[:] = 0.0

    def apply(self, stage: int, ref_p: np.ndarray, ref_v: np.ndarray, ref_a: np.ndarray,
              ref_j: np.ndarray) -> None:
        """Add this tick's offsets of ``stage`` (0: before the shapers, 1: after them) to
        the reference (arrays of shape (2,)) in place."""
        compensate_reference(self.par, self.state, self.period, stage, ref_p, ref_v, ref_a,
                             ref_j)


NO_COMPENSATION = (np.zeros((0, 5)), np.zeros((2, 5)))
"""``compensate_reference``'s ``par`` and ``state`` that add nothing."""


def curve_quartic(shapers: Sequence[InputShaper | None], tolerance: float,
                  share: float) -> float:
    """The planner's cap on curves with the smoothing compensation: a curve of curvature κ
    at centripetal acceleration a_n keeps ``g4·a_n²·κ`` of the shapers' error
    (``smoothing_quartic``, the larger axis'), which stays within ``share·tolerance`` (m)
    when ``a_n ≤ 1/√(q·κ)``; returns q = |g4|/(share·tolerance) (s⁴/m), 0 for no cap."""
    g4 = max((abs(smoothing_quartic(s)) for s in shapers if s is not None), default=0.0)
    if g4 <= 0.0 or share <= 0.0 or not math.isfinite(tolerance):
        return 0.0
    return g4 / (share * tolerance)


def curvature_step_error(shaper: InputShaper, *, compensated: bool = True,
                         samples: int = 2001) -> float:
    """χ (s²): the largest contour error of a shaped reference where the path's normal
    acceleration steps by a_n (a line meeting an arc at speed) is ``χ·a_n``.

    Locally the path is ``(v·t, ½·a_n·t²·H(t))``; the shaped point is
    ``(v·(t − τ), Σ A_i·(½·a_n·(t − t_i)² − c·a_n)·H(t − t_i))`` with c = σ²/2 under the
    smoothing compensation (0 without), against the path's ``½·a_n·(t − τ)²·H(t − τ)``
    there. Without the compensation the error settles at σ²/2 (the steady shrink); with
    it only the transient is left: the first impulse puts A_0·σ²/2 outward before the
    arc's start reaches the others (EI: 0.66·σ²/2).
    """
    a, t = np.asarray(shaper.amplitudes), np.asarray(shaper.times)
    tau = float(np.dot(a, t))
    c = 0.5 * float(np.dot(a, (t - tau) ** 2)) if compensated else 0.0
    grid = np.linspace(0.0, 1.5 * t[-1] + 1e-9, samples)
    d = grid[:, None] - t[None, :]
    shaped = np.sum(a * np.where(d > 0.0, 0.5 * d * d - c, 0.0), axis=1)
    path = np.where(grid > tau, 0.5 * (grid - tau) ** 2, 0.0)
    return float(np.abs(shaped - path).max())


def curve_step_acceleration(shapers: Sequence[InputShaper | None], tolerance: float,
                            share: float) -> float:
    """The largest step of the normal acceleration (m/s²) a node may have with the
    smoothing compensation: ``share·tolerance/χ`` (``curvature_step_error`` of the larger
    axis' shaper); ``inf`` without a shaper or with ``share`` 0."""
    chi = max((curvature_step_error(s) for s in shapers if s is not None), default=0.0)
    if chi <= 0.0 or share <= 0.0:
        return math.inf
    return share * tolerance / chi
