"""Input shapers: each axis' position reference filtered after interpolation.

An input shaper is a train of impulses ``A_i`` at times ``t_i`` (``ΣA_i = 1``); convolved
with a reference it cancels the residual vibration of a lightly damped mode at frequency
``f`` with damping ratio ``ζ`` (Singer & Seering 1990; Singhose et al. 1994, 1996). With
``ω_d = 2πf·√(1 − ζ²)``, the damped period ``T_d = 2π/ω_d`` and
``K = exp(−ζπ/√(1 − ζ²))``:

=========  ==================================================  ==========================
shaper     amplitudes (before ``K`` and normalising to sum 1)  times (× T_d)
=========  ==================================================  ==========================
ZV         1, 1                                                0, ½
MZV        1 − 1/√2, √2 − 1, 1 − 1/√2  (K^¾ per step)          0, ⅜, ¾
ZVD        1, 2, 1                                             0, ½, 1
EI         (1+V)/4, (1−V)/2, (1+V)/4                           0, ½, 1
2-hump EI  a, ½ − a, ½ − a, a;  a = (3X² + 2X + 3V²)/(16X),    0, ½, 1, 3/2
           X = (V²(√(1 − V²) + 1))^⅓
3-hump EI  a, (1−V)/4, 1 − 2a − (1−V)/2, (1−V)/4, a;           0, ½, 1, 3/2, 2
           a = (1 + 3V + 2√(2V(V + 1)))/16
=========  ==================================================  ==========================

``V = V_TOL`` (5 %) is the EI shapers' vibration tolerance. Damping enters as in Singer &
Seering's derivation of ZV and ZVD: the i-th impulse (``t_i = i·T_d/2``) is multiplied by
``K^i`` (MZV: ``t_i = i·3T_d/8``, ``K^(3i/4)``) before normalising. For ZV, MZV and ZVD this
keeps the residual vibration at the design point exactly zero for any ζ. For the EI shapers it
keeps the design point where the undamped shaper has it, and the vibration there becomes
``V_TOL·K^(n−1)/ΣA_iK^i`` (below ``V_TOL``; ``design_residual``): the damped EI shapers of
Singhose's later curve fits are not used.

Residual vibration (Singer & Seering): the vibration left when the last impulse is given,
relative to the vibration an unshaped step starts with::

    V(ω, ζ) = e^(−ζω·t_n) · |Σ A_i e^(ζω·t_i) e^(jω√(1−ζ²)·t_i)|

Delay. A shaped move ends ``duration = t_n`` later than the raw one (ZV: T_d/2; MZV: ¾T_d;
ZVD, EI: T_d; 2-hump EI: 3/2·T_d; 3-hump EI: 2·T_d): the cycle time grows by that much once
per stop. Along a path at constant velocity the shaped reference lags by the impulses'
centroid ``lag = Σ A_i t_i`` (ZV at ζ = 0: T_d/4), which the following error shows as
a constant offset along the path, not across it.

Applied each tick (``ReferenceShaper``): the reference the interpolator produced for each
axis (position, velocity, acceleration and jerk) is passed through the shaper as a FIR on
the controller's period T. An impulse at ``t = (m + φ)·T`` between two samples is split
linearly: ``(1 − φ)·A`` at m and ``φ·A`` at m + 1. For a mode of frequency ω that replaces
``e^(jωφT)`` by ``(1 − φ) + φ·e^(jωT)``, an error of at most ``φ(1 − φ)(ωT)²/2`` per
impulse: the discrete shaper's residual vibration at the design point is at most
``(ωT)²/8`` above the continuous one (laser_belt, 16 Hz at 3.5 ms: 1.5 %; a mode near the
Nyquist rate cannot be shaped). ``InputShaper.taps`` gives the discrete impulses, and
``residual_vibration`` of them the vibration the filter really leaves. The same FIR on v, a
and j keeps them the exact time derivatives of the shaped position (a linear filter
commutes with d/dt), so the regulator's feed-forward and the DCU follow the shaped
reference.

Contour. The same shaper on both axes is one linear filter of the path: a point on a
straight line stays on it (the shaped point is a convex combination of earlier points of
the line, every amplitude being positive), a corner is cut, and a circle of radius R run at
``Ω = v/R`` shrinks to ``R·|H(Ω)|``, ``H(Ω) = ΣA_i e^(−jΩt_i)``: a radial error
``≈ v²σ²/(2R)`` with σ² the impulses' time variance (``circle_error``). Different
shapers on x and y also move straight lines sideways (the axes lag differently).
``twin shaper`` measures these errors in closed-loop runs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from twin.config import AXES, AxisConfig, moving_masses
from twin.errors import ConfigError

__all__ = ["NO_TAPS", "SHAPERS", "V_TOL", "InputShaper", "ReferenceShaper", "axis_shapers",
           "believed_mode", "circle_error", "design", "residual_vibration", "shape_reference"]

SHAPERS = ("zv", "mzv", "zvd", "ei", "2hump-ei", "3hump-ei")
"""The input shapers, by name (``twin.config.shaper_settings.SHAPER_TYPES`` adds "none")."""

V_TOL = 0.05
"""The EI shapers' vibration tolerance (5 % of the unshaped vibration)."""

_SQRT2 = math.sqrt(2.0)


def _undamped(name: str, v: float) -> tuple[list[float], float, float]:
    """Amplitudes at ζ = 0, the time step between impulses (× T_d) and the damping
    exponent per step (``K`` to this power per impulse)."""
    if name == "zv":
        return [0.5, 0.5], 0.5, 1.0
    if name == "mzv":
        a = 1.0 - 1.0 / _SQRT2
        return [a, _SQRT2 - 1.0, a], 0.375, 0.75
    if name == "zvd":
        return [0.25, 0.5, 0.25], 0.5, 1.0
    if name == "ei":
        return [0.25 * (1.0 + v), 0.5 * (1.0 - v), 0.25 * (1.0 + v)], 0.5, 1.0
    if name == "2hump-ei":
        v2 = v * v
        x = (v2 * (math.sqrt(1.0 - v2) + 1.0)) ** (1.0 / 3.0)
        a = (3.0 * x * x + 2.0 * x + 3.0 * v2) / (16.0 * x)
        return [a, 0.5 - a, 0.5 - a, a], 0.5, 1.0
    if name == "3hump-ei":
        a = (1.0 + 3.0 * v + 2.0 * math.sqrt(2.0 * v * (v + 1.0))) / 16.0
        b = 0.25 * (1.0 - v)
        return [a, b, 1.0 - 2.0 * (a + b), b, a], 0.5, 1.0
    raise ConfigError("shaper", f"unknown shaper {name!r}; one of {', '.join(SHAPERS)}")


@dataclass(frozen=True)
class InputShaper:
    """One designed shaper: impulses ``amplitudes`` at ``times``.

    Attributes
    ----------
    name : str
        One of ``SHAPERS``.
    frequency : float
        Design frequency (Hz): the undamped natural frequency of the mode.
    damping : float
        Design damping ratio (1).
    amplitudes : tuple of float
        Impulse amplitudes (1), summing to 1.
    times : tuple of float
        Impulse times (s), the first 0.
    """

    name: str
    frequency: float
    damping: float
    amplitudes: tuple[float, ...]
    times: tuple[float, ...]

    @property
    def duration(self) -> float:
        """Time from the first to the last impulse (s): how much later a shaped move ends."""
        return self.times[-1]

    @property
    def lag(self) -> float:
        """The impulses' centroid ``ΣA_i·t_i`` (s): the shaped reference's lag at constant
        velocity."""
        return float(np.dot(self.amplitudes, self.times))

    @property
    def spread(self) -> float:
        """Standard deviation of the impulse times about the centroid (s)."""
        t, a = np.asarray(self.times), np.asarray(self.amplitudes)
        return float(np.sqrt(np.dot(a, (t - self.lag) ** 2)))

    def residual(self, frequency, damping=None):
        """``residual_vibration`` of this shaper at ``frequency`` (Hz, scalar or array)
        and ``damping`` (default the design damping)."""
        return residual_vibration(self.amplitudes, self.times, frequency,
                                  self.damping if damping is None else damping)

    def design_residual(self) -> float:
        """The residual vibration at the design point, analytically: 0 for ZV, MZV, ZVD and
        2-hump EI, ``V_TOL·K^(n−1)/ΣB_iK^i`` for EI and 3-hump EI (B the undamped
        amplitudes)."""
        if self.name not in ("ei", "3hump-ei"):
            return 0.0
        base, _, power = _undamped(self.name, V_TOL)
        k = _k(self.damping) ** power
        return V_TOL * k ** (len(base) - 1) / sum(b * k**i for i, b in enumerate(base))

    def taps(self, period: float) -> tuple[np.ndarray, np.ndarray]:
        """The shaper as a FIR on the controller period (see the module docstring).

        Returns
        -------
        index : ndarray of int64, shape (m,)
            Delays of the taps (periods), increasing.
        weight : ndarray, shape (m,)
            Their weights (1), summing to 1.
        """
        if not (math.isfinite(period) and period > 0.0):
            raise ConfigError("period", f"must be > 0 (s), got {period!r}")
        acc: dict[int, float] = {}
        for a, t in zip(self.amplitudes, self.times, strict=True):
            q = t / period
            m = math.floor(q)
            phi = q - m
            if phi < 1e-9:
                phi = 0.0
            elif phi > 1.0 - 1e-9:
                m, phi = m + 1, 0.0
            acc[m] = acc.get(m, 0.0) + a * (1.0 - phi)
            if phi > 0.0:
                acc[m + 1] = acc.get(m + 1, 0.0) + a * phi
        index = np.array(sorted(acc), dtype=np.int64)
        return index, np.array([acc[int(i)] for i in index])

    def discrete(self, period: float) -> InputShaper:
        """The shaper as the FIR applies it at ``period`` (s): its taps as impulses."""
        index, weight = self.taps(period)
        return InputShaper(self.name, self.frequency, self.damping,
                           tuple(weight.tolist()), tuple((index * period).tolist()))


def _k(damping: float) -> float:
    return math.exp(-damping * math.pi / math.sqrt(1.0 - damping * damping))


def design(name: str, frequency: float, damping: float = 0.0, *,
           tolerance: float = V_TOL) -> InputShaper:
    """The shaper ``name`` for a mode at ``frequency`` (Hz) with ``damping`` ratio.

    Parameters
    ----------
    name : str
        One of ``SHAPERS``.
    frequency : float
        Undamped natural frequency of the mode (Hz), > 0.
    damping : float
        Damping ratio of the mode, 0 ≤ ζ < 1.
    tolerance : float
        The EI shapers' vibration tolerance V (1).

    Raises
    ------
    ConfigError
        ``shaper`` (unknown name), ``frequency`` or ``damping`` out of range.
    """
    if not (math.isfinite(frequency) and frequency > 0.0):
        raise ConfigError("frequency", f"must be > 0 (Hz), got {frequency!r}")
    if not (math.isfinite(damping) and 0.0 <= damping < 1.0):
        raise ConfigError("damping", f"must lie in [0, 1), got {damping!r}")
    base, step, power = _undamped(name, tolerance)
    root = math.sqrt(1.0 - damping * damping)
    t_d = 1.0 / (frequency * root)
    k = _k(damping) ** power
    scaled = [b * k**i for i, b in enumerate(base)]
    total = sum(scaled)
    return InputShaper(name, float(frequency), float(damping),
                       tuple(a / total for a in scaled),
                       tuple(i * step * t_d for i in range(len(base))))


def residual_vibration(amplitudes: Sequence[float], times: Sequence[float], frequency,
                       damping):
    """Singer & Seering's residual vibration of impulses on a mode (1).

    Parameters
    ----------
    amplitudes, times : sequence of float
        The impulses (1) and their times (s).
    frequency : float or array_like
        Undamped natural frequency of the mode (Hz).
    damping : float or array_like
        Its damping ratio (broadcast against ``frequency``).

    Returns
    -------
    float or ndarray
        ``e^(−ζω·t_n)·|ΣA_i e^(ζω·t_i + jω_d·t_i)|``: 1 for one unit impulse, 0 where the
        shaper cancels the mode.
    """
    a = np.asarray(amplitudes, dtype=float)
    t = np.asarray(times, dtype=float)
    w = 2.0 * np.pi * np.asarray(frequency, dtype=float)[..., None]
    z = np.asarray(damping, dtype=float)[..., None]
    wd = w * np.sqrt(1.0 - z * z)
    terms = a * np.exp(z * w * (t - t[-1]))
    c = np.sum(terms * np.cos(wd * t), axis=-1)
    s = np.sum(terms * np.sin(wd * t), axis=-1)
    out = np.hypot(c, s)
    return float(out) if out.ndim == 0 else out


def circle_error(shaper: InputShaper, radius: float, speed: float) -> float:
    """How much a circle of ``radius`` (m) run at ``speed`` (m/s) shrinks when both axes'
    references go through ``shaper``: ``R·(1 − |H(v/R)|)`` (m), the reference's own contour
    error (the loop adds its own)."""
    omega = speed / radius
    h = np.sum(np.asarray(shaper.amplitudes) * np.exp(-1j * omega * np.asarray(shaper.times)))
    return float(radius * (1.0 - abs(h)))


def believed_mode(axes: Mapping[str, AxisConfig], axis: str) -> tuple[float, float]:
    """The first elastic mode of ``axis`` as the controller's model of the machine has it:
    ``√(k/m)/2π`` (Hz) of the transmission's series stiffness and the moving mass (the motor
    held by its speed loop; the x axis carries the y carriage), and the transmission's
    damping ratio. The corner model uses the same mode (``SeedCornerModel.from_axes``)."""
    tr = axes[axis].transmission
    mass = moving_masses(axes)[axis]
    return math.sqrt(tr.axial_stiffness / mass) / (2.0 * math.pi), tr.damping_ratio


def axis_shapers(settings: Any, axes: Mapping[str, AxisConfig], period: float
                 ) -> tuple[InputShaper | None, InputShaper | None]:
    """The x and y shapers of the machine's ``controller.shaper`` settings (``ShaperAxes``);
    an unset frequency or damping is the believed axes' mode (``believed_mode``).

    Raises
    ------
    ConfigError
        ``controller.shaper.<axis>.frequency`` when the model's mode is not below the
        Nyquist rate of the controller period (it cannot be shaped: set the frequency).
    """
    out = []
    for axis in AXES:
        s = getattr(settings, axis)
        if s.type == "none":
            out.append(None)
            continue
        f, z = believed_mode(axes, axis)
        if s.frequency is None and f >= 0.5 / period:
            raise ConfigError(f"controller.shaper.{axis}.frequency", f"unset, and the "
                              f"model's mode ({f:.4g} Hz) is not below the Nyquist rate of "
                              f"the controller period ({0.5 / period:g} Hz): set one")
        out.append(design(s.type, s.frequency if s.frequency is not None else f,
                          s.damping if s.damping is not None else z))
    return out[0], out[1]


# --------------------------------------------------------------------------- the filter
@numba.njit(cache=True)
def shape_reference(index, weight, history, state, ref_p, ref_v, ref_a, ref_j):
    """One tick of the shapers of both axes, in place (the one implementation: the Python
    tick and the compiled tick both call it).

    ``index`` (2, m) int64 and ``weight`` (2, m): each axis' taps (unused ones weigh 0);
    ``history`` (2, 4, n): the last n raw references of each axis (p, v, a, j), a ring
    whose newest slot is ``state[0]``. The raw reference is pushed, then each channel is
    replaced by ``x₀ + Σ w_i·(x_{−index_i} − x₀)`` (x₀ the newest sample): ``Σ w_i·x`` when
    the weights sum to 1, and exactly x₀ when the reference stands still. No taps: nothing.
    """
    m = index.shape[1]
    if m == 0:
        return
    n = history.shape[2]
    head = (state[0] + 1) % n
    state[0] = head
    for k in range(2):
        history[k, 0, head] = ref_p[k]
        history[k, 1, head] = ref_v[k]
        history[k, 2, head] = ref_a[k]
        history[k, 3, head] = ref_j[k]
    for k in range(2):
        for c in range(4):
            newest = history[k, c, head]
            acc = 0.0
            for i in range(m):
                acc += weight[k, i] * (history[k, c, (head - index[k, i] + n) % n] - newest)
            value = newest + acc
            if c == 0:
                ref_p[k] = value
            elif c == 1:
                ref_v[k] = value
            elif c == 2:
                ref_a[k] = value
            else:
                ref_j[k] = value


class ReferenceShaper:
    """The shapers of both axes as a FIR over the ticks (``shape_reference``).

    Parameters
    ----------
    shapers : sequence of 2 InputShaper or None
        The x and y shapers; None leaves that axis as it is.
    period : float
        Controller period (s).

    Attributes
    ----------
    index, weight : ndarray, shape (2, m)
        The taps (``InputShaper.taps``), padded with zero weights.
    history : ndarray, shape (2, 4, n)
        The raw references of the last n ticks (ring buffer).
    state : ndarray of int64, shape (1,)
        The ring's newest slot.
    """

    def __init__(self, shapers: Sequence[InputShaper | None], period: float):
        if len(shapers) != 2:
            raise ConfigError("shapers", f"must be 2 (x, y), got {len(shapers)}")
        self.shapers = tuple(shapers)
        self.period = float(period)
        taps = [s.taps(period) if s is not None else (np.zeros(1, np.int64), np.zeros(1))
                for s in shapers]
        m = max(t[0].size for t in taps)
        self.index = np.zeros((2, m), dtype=np.int64)
        self.weight = np.zeros((2, m))
        for k, (idx, w) in enumerate(taps):
            self.index[k, :idx.size], self.weight[k, :w.size] = idx, w
        self.history = np.zeros((2, 4, int(self.index.max()) + 1))
        self.state = np.zeros(1, dtype=np.int64)

    @property
    def active(self) -> bool:
        """Whether any axis is shaped."""
        return any(s is not None for s in self.shapers)

    @property
    def duration(self) -> float:
        """The longest delay of the taps (s): the shaped reference stands still this long
        after the raw one does."""
        return float(self.index.max()) * self.period

    def reset(self, position: Sequence[float]) -> None:
        """At rest at ``position`` (m): every past reference there, v = a = j = 0."""
        self.history[:] = 0.0
        self.history[0, 0, :] = position[0]
        self.history[1, 0, :] = position[1]
        self.state[0] = 0

    def apply(self, ref_p: np.ndarray, ref_v: np.ndarray, ref_a: np.ndarray,
              ref_j: np.ndarray) -> None:
        """Push one tick's raw reference (arrays of shape (2,)) and write the shaped one
        into the same arrays."""
        shape_reference(self.index, self.weight, self.history, self.state, ref_p, ref_v,
                        ref_a, ref_j)


NO_TAPS = (np.zeros((2, 0), dtype=np.int64), np.zeros((2, 0)), np.zeros((2, 4, 1)),
           np.zeros(1, dtype=np.int64))
"""``shape_reference``'s arguments that shape nothing (no shaper configured)."""
