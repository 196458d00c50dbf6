"""The speed and tangential limits one path segment allows (the planner's V_segment).

A segment's speed cap and the tangential acceleration and jerk its profile may use follow
from the contour limits, the per-axis limits projected on the direction of travel, and —
on curved segments — the acceleration and jerk that the curvature itself demands:

* line, direction t̂: ``v ≤ v_max_k/|t̂_k|``, ``a ≤ a_max_k/|t̂_k|``, ``j ≤ j_max_k/|t̂_k|``
  for each axis k, and the contour limits;
* arc or spline: the tangent turns, so the per-axis velocity limit uses the largest
  ``|t̂_k|`` over the segment (exact for an arc, from its angle range; for a spline
  sampled, with a margin for what lies between samples), and the total acceleration and
  jerk vectors are kept within ``A = min(contour, axes)`` and ``J = min(contour, axes)``.
  With κ the largest |curvature| and κ' the largest |dκ/ds|, the acceleration
  ``a = s̈·t̂ + v²κ·n̂`` and the jerk ``j = (s⃛ − v³κ²)·t̂ + (3·v·s̈·κ + v³κ')·n̂`` are
  held by this split of the budgets (issue 30; it was ``v²κ ≤ A/√2``, ``v³(κ² + κ') ≤ J/4``,
  ``3·v·a_t·κ ≤ J/2``, the components summed):

  ===========================  ==================================================
  speed cap, centripetal       ``v²κ ≤ CENTRIPETAL·A`` (0.8: at the cap a_t ≥ 0.6·A)
  speed cap, jerk at cruise    ``v³·√(κ⁴ + κ'²) ≤ CRUISE_JERK·J`` (one half)
  tangential acceleration      ``a_t = √(A² − (v²κ)²)``, so ``|a| ≤ A``
  jerk, tangential component   ``|s⃛| + v³κ² ≤ 0.8·J``: ``j_t = 0.8·J − v³κ² ≥ 0.3·J``
  jerk, normal component       ``3·v·a_t·κ + v³κ' ≤ 0.6·J``: ``a_t ≤ (0.6·J − v³κ')/(3vκ)``
  ===========================  ==================================================

  The two jerk components are the legs of a right triangle whose hypotenuse is J
  (0.8² + 0.6² = 1), so ``|j| ≤ J`` at every speed up to the cap and every tangential
  acceleration and jerk within the block's limits.
  A law that does not limit jerk (the trapezoid, ``jerk=False``) gets no jerk caps: its
  own acceleration steps are impulses of jerk anyway.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from twin.controller.geometry import Arc, Line, Segment
from twin.controller.profiles import Limits

__all__ = ["CENTRIPETAL", "CRUISE_JERK", "JERK_NORMAL", "JERK_TANGENTIAL", "SegmentLimits"]

CENTRIPETAL = 0.8
"""Share of the total acceleration A that a curve's speed cap may give the centripetal
acceleration v²κ (the rest, ≥ √(1 − 0.64)·A = 0.6·A, is the tangential acceleration's: a
block has one tangential limit, and a whole circle must still get up to speed on it)."""
CRUISE_JERK = 0.5
"""Share of the total jerk J that a curve's speed cap may give the jerk of cruising along
it, v³·√(κ⁴ + κ'²)."""
JERK_TANGENTIAL, JERK_NORMAL = 0.8, 0.6
"""The jerk's tangential and normal components are held to these shares of J (their
squares sum to 1: |j| ≤ J)."""


class SegmentLimits:
    """Speed caps and tangential limits of segments under contour and per-axis limits.

    Parameters
    ----------
    limits : Limits
        Contour limits (m/s, m/s², m/s³). ``max_velocity`` is not used here: the caller
        passes the speed cap it wants (feed or rapid speed) to `caps`.
    axis_limits : sequence of 2 Limits
        Limits of the x and y axes.
    jerk : bool
        Cap the speed on curves by the jerk the curvature demands (laws that limit jerk).
    curve_acceleration : float
        A further cap of the centripetal acceleration v²κ (m/s²): the input shapers'
        (``twin.controller.shaped_corner.curve_acceleration``); default none.
    curve_quartic : float
        q (s⁴/m): a cap ``v²κ ≤ 1/√(q·κ)`` on curves, the shapers' fourth-order error once
        the smoothing compensation removed the second-order one
        (``twin.controller.compensation.curve_quartic``); 0: none. When set,
        ``curve_acceleration`` caps only the blends (the rounded kinks).
    """

    def __init__(self, limits: Limits, axis_limits: Sequence[Limits], *, jerk: bool = True,
                 curve_acceleration: float = math.inf, curve_quartic: float = 0.0):
        self.limits = limits
        self.axis_limits = tuple(axis_limits)
        self.jerk = jerk
        self.curve_acceleration = float(curve_acceleration)
        self.curve_quartic = float(curve_quartic)
        self._axis_caps = tuple((lim.max_velocity, lim.max_acceleration, lim.max_jerk)
                                for lim in self.axis_limits)
        if len(self._axis_caps) != 2:
            raise ValueError(f"axis_limits: two axes (x, y), got {len(self._axis_caps)}")
        lx, ly = self.axis_limits
        # the acceleration and jerk a curve may use in total (normal and tangential)
        self._curve_totals = a_tot, j_tot = (
            min(limits.max_acceleration, lx.max_acceleration, ly.max_acceleration),
            min(limits.max_jerk, lx.max_jerk, ly.max_jerk))
        # the budgets' shares, per segment: computed once (the same products)
        self._centripetal = min(CENTRIPETAL * a_tot, self.curve_acceleration)
        self._a_tot2 = a_tot * a_tot
        self._jerk_shares = (CRUISE_JERK * j_tot, JERK_NORMAL * j_tot, JERK_TANGENTIAL * j_tot)

    def caps(self, segment: Segment, v_cap: float) -> tuple[float, float, float]:
        """(speed cap (m/s), tangential acceleration (m/s²), tangential jerk (m/s³))."""
        if type(segment) is Line:
            return self.line_caps(abs(segment._ux), abs(segment._uy), v_cap)
        return self.curve_caps(segment, v_cap)

    def line_caps(self, ax: float, ay: float, v_cap: float) -> tuple[float, float, float]:
        """Caps of a straight segment with direction components ``|t̂_x|, |t̂_y|``."""
        c = self.limits
        v, a, j = v_cap, c.max_acceleration, c.max_jerk
        (xv, xa, xj), (yv, ya, yj) = self._axis_caps   # per block: unrolled
        if ax * v > xv:
            v = xv / ax
        if ax * a > xa:
            a = xa / ax
        if ax * j > xj:
            j = xj / ax
        if ay * v > yv:
            v = yv / ay
        if ay * a > ya:
            a = ya / ay
        if ay * j > yj:
            j = yj / ay
        return v, a, j

    def curve_caps(self, seg: Segment, v_cap: float, blend: bool = False
                   ) -> tuple[float, float, float]:
        """Caps of an arc (exact) or any other curved segment (sampled); ``blend``: the
        arc rounds a kink (``twin.controller.blend``)."""
        lx, ly = self.axis_limits
        if type(seg) is Arc:
            if v_cap <= lx.max_velocity and v_cap <= ly.max_velocity:
                mx = my = 0.0          # a tangent component ≤ 1: no axis can cap the speed
            else:
                mx, my = _arc_tangent_extent(seg)
            kappa, dkappa = 1.0 / seg.radius, 0.0
        else:
            mx, my, kappa, dkappa = _sampled_extent(seg)
        v = v_cap
        if mx * v > lx.max_velocity:
            v = lx.max_velocity / mx
        if my * v > ly.max_velocity:
            v = ly.max_velocity / my
        if kappa > 0.0:
            if self.curve_quartic > 0.0:
                # compensated: the shapers' fourth-order error on a curve; a blend is a
                # corner, shorter than the shapers, which the compensation cannot reach
                a_cap = min(CENTRIPETAL * self._curve_totals[0],
                            1.0 / math.sqrt(self.curve_quartic * kappa))
                if blend:
                    a_cap = min(a_cap, self.curve_acceleration)
            else:
                a_cap = self._centripetal
            cap = math.sqrt(a_cap / kappa)
            if cap < v:
                v = cap
            if self.jerk:
                cap = (self._jerk_shares[0] / math.hypot(kappa * kappa, dkappa)) ** (1.0 / 3.0)
                if cap < v:
                    v = cap
        return (v, *self.tangential(v, kappa, dkappa))

    def tangential(self, v: float, kappa: float, dkappa: float = 0.0) -> tuple[float, float]:
        """Tangential acceleration (m/s²) and jerk (m/s³) a curve of largest curvature
        ``kappa`` (1/m) and curvature rate ``dkappa`` (1/m²) allows at speeds up to ``v``
        (m/s, within its speed cap): the split of the budgets in the module doc."""
        a_n = v * v * kappa
        a_t2 = self._a_tot2 - a_n * a_n
        a_t = math.sqrt(0.0 if 0.0 > a_t2 else a_t2)
        if not self.jerk:
            return a_t, self._curve_totals[1]
        _, normal, tangential = self._jerk_shares
        v3 = v * v * v
        if kappa > 0.0:
            cap = (normal - v3 * dkappa) / (3.0 * v * kappa)
            if cap < a_t:
                a_t = cap
        return a_t, tangential - v3 * kappa * kappa


def _max_abs_sin(a: float, b: float) -> float:
    """max |sin φ| for φ in [a, b] (a ≤ b)."""
    if b - a >= math.pi:
        return 1.0
    k = math.ceil((a - 0.5 * math.pi) / math.pi)
    if 0.5 * math.pi + k * math.pi <= b:
        return 1.0
    return max(abs(math.sin(a)), abs(math.sin(b)))


def _arc_tangent_extent(arc: Arc) -> tuple[float, float]:
    """Largest |tangent component| over the arc, (x, y): exact from its angle range."""
    th0 = arc._theta0                  # atan2 of start − centre (same package)
    a, b = (th0, th0 + arc.sweep) if arc.sweep >= 0.0 else (th0 + arc.sweep, th0)
    return _max_abs_sin(a, b), _max_abs_sin(a + 0.5 * math.pi, b + 0.5 * math.pi)


def _sampled_extent(seg: Segment, n: int = 65) -> tuple[float, float, float, float]:
    """Tangent extent, max |κ| and max |dκ/ds| of a general segment from ``n`` samples.

    Between samples h apart the tangent turns by at most κ·h, so a tangent component can
    exceed its sampled maximum by at most κ·h/2 (and κ by |κ'|·h/2): both margins are added,
    so the caps stay on the safe side.
    """
    s = np.linspace(0.0, seg.length, n)
    h = seg.length / (n - 1)
    t = np.abs(seg.tangent(s))
    k = np.abs(np.asarray(seg.curvature(s), dtype=float))
    dk = float((np.abs(np.diff(k)) / h).max()) if n > 1 else 0.0
    kappa = float(k.max()) + 0.5 * dk * h
    margin = 0.5 * kappa * h
    return (min(1.0, float(t[:, 0].max()) + margin), min(1.0, float(t[:, 1].max()) + margin),
            kappa, dk)
