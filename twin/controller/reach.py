"""Monotone reachable speed over one block: what the look-ahead passes may rely on.

``max_end_speed(law, v, d, limits)`` is the highest speed one speed change of the law
reaches after ``d`` of path from ``v``. For every law but the trapezoid it is *not*
monotone in ``v``: a change that must start and end at zero acceleration covers
``(v + v1)/2 · T(v1 − v)`` of path, so starting faster can leave less room to gain speed
(in the jerk-limited regime ``f`` falls while ``f(v) − v > 2v``; the S-curve also falls for
``v < A²/(2J)`` in its acceleration-limited regime). The grbl-style passes need a monotone
relation — raising the speed at one node must never shrink what its neighbour may do — so
the planner uses the lower monotone envelope

    g(v) = min over u ≥ v of f(u)  ≤  f(v),

which is as large as safety allows. ``f(u) − 3u`` is strictly decreasing, so its root u_r
is unique; the local minima of ``f`` lie at u_r and (S-curve) at ``A²/(2J)``, hence
``g(v) = min(f(v), f(u_r) if v < u_r, f(A²/(2J)) if v < A²/(2J))``. A node pair
``(low, high)`` with ``high ≤ g(low)`` is a feasible speed change of the law
(``plan_move`` accepts it).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba

from twin.controller.profiles import Limits, max_end_speed
from twin.controller.profiles.closed_forms import (
    SCURVE_KIND,
    TRAPEZOID_KIND,
    capped_end_speed,
)
from twin.controller.profiles.laws import law_code

__all__ = ["ReachFloor", "floor_of", "guesses", "monotone_end_speed", "reach_floor",
           "reach_function", "reach_of", "root_3u"]

ReachFloor = tuple[float, float, float, float]
"""(u1, f(u1), u2, f(u2)): the candidate minima of ``f`` for one block (m/s)."""



@numba.njit(cache=True, inline="always")
def guesses(kind: int, ka: float, kj: float, d: float, a: float,
            j: float) -> tuple[float, float]:
    """Closed-form roots of f(u) = 3u (Δv = 2u) in the jerk- and acceleration-limited
    regimes of the law's closed forms (`twin.controller.profiles.laws`; ``law_code``)."""
    if kind == SCURVE_KIND:            # d = (u + Δv/2)·2√(Δv/J);  d = 2u·(2u/A + A/J)
        return ((j * d * d / 32.0) ** (1.0 / 3.0),
                0.125 * a * (math.sqrt(4.0 * a * a / (j * j) + 16.0 * d / a) - 2.0 * a / j))
    # d = (u + Δv/2)·√(k_j·Δv/J);  d = k_a·(9u² − u²)/(2A)
    return (j * d * d / (8.0 * kj)) ** (1.0 / 3.0), math.sqrt(a * d / (4.0 * ka))


@numba.njit(cache=True)
def root_3u(kind: int, ka: float, kj: float, d: float, cap: float, a: float, j: float,
            g1: float, g2: float) -> float:
    """The root u of ``max_end_speed(u) = 3u`` (m/s): the closed form of whichever regime
    holds there (the ``guesses`` ``g1``, ``g2``, checked), else the Illinois method to
    1e-12 relative."""
    for u in (g1, g2):
        if abs(capped_end_speed(kind, ka, kj, u, d, cap, a, j) - 3.0 * u) <= 1e-12 * u:
            return u
    lo, hi = 0.0, capped_end_speed(kind, ka, kj, 0.0, d, cap, a, j)
    h_lo, h_hi = hi, capped_end_speed(kind, ka, kj, hi, d, cap, a, j) - 3.0 * hi
    if h_hi >= 0.0:                      # capped at max_velocity: the root is the cap / 3
        return hi
    side = 0
    for _ in range(100):
        u = (lo * h_hi - hi * h_lo) / (h_hi - h_lo)
        h = capped_end_speed(kind, ka, kj, u, d, cap, a, j) - 3.0 * u
        if h == 0.0:
            return u
        if h > 0.0:
            lo, h_lo = u, h
            if side == 1:
                h_hi *= 0.5
            side = 1
        else:
            hi, h_hi = u, h
            if side == -1:
                h_lo *= 0.5
            side = -1
        if hi - lo <= 1e-12 * hi:
            break
    return 0.5 * (lo + hi)


@numba.njit(cache=True)
def floor_of(kind: int, ka: float, kj: float, d: float, cap: float, a: float,
             j: float) -> tuple[float, float, float, float]:
    """``reach_floor`` in the kernels' terms (``law_code``; the block's length, speed cap,
    acceleration and jerk): the one implementation, for the planner's compiled window
    and for the Python callers."""
    if kind == TRAPEZOID_KIND:
        return 0.0, 0.0, 0.0, 0.0
    g1, g2 = guesses(kind, ka, kj, d, a, j)
    # the S-curve's other candidate, A²/(2J): a·a, not a ** 2 (correctly rounded)
    u2 = a * a / (2.0 * j)
    if 3.0 * min(g1, g2) >= cap and capped_end_speed(kind, ka, kj, 0.0, d, cap, a, j) >= cap \
            and (kind != SCURVE_KIND or capped_end_speed(kind, ka, kj, u2, d, cap, a, j)
                 >= cap):
        # f(0), every f(u_r) = 3·u_r ≥ 3·min(closed-form roots) and the S-curve's f(A²/2J)
        # all reach the cap: f is the constant cap, nothing to correct (long blocks)
        return 0.0, 0.0, 0.0, 0.0
    u1 = root_3u(kind, ka, kj, d, cap, a, j, g1, g2)
    f1 = capped_end_speed(kind, ka, kj, u1, d, cap, a, j)
    if kind != SCURVE_KIND:            # the shape laws rise in their acceleration regime
        return u1, f1, 0.0, 0.0
    return u1, f1, u2, capped_end_speed(kind, ka, kj, u2, d, cap, a, j)


def reach_floor(law: str, distance: float, limits: Limits) -> ReachFloor:
    """Candidate minima of ``max_end_speed(law, ·, distance, limits)`` (see module doc)."""
    if not distance >= 0.0:
        max_end_speed(law, 0.0, distance, limits)   # raises, naming it
    kind, ka, kj = law_code(law)
    return floor_of(kind, ka, kj, float(distance), limits.max_velocity,
                    limits.max_acceleration, limits.max_jerk)


def monotone_end_speed(law: str, v: float, distance: float, limits: Limits,
                       floor: ReachFloor) -> float:
    """g(v) = min over u ≥ v of ``max_end_speed(law, u, distance, limits)`` (m/s).

    Parameters
    ----------
    law : str
        Acceleration law.
    v : float
        Speed at one end of the block (m/s).
    distance : float
        Block length (m).
    limits : Limits
        The block's tangential limits.
    floor : ReachFloor
        ``reach_floor(law, distance, limits)``, computed once per block.
    """
    return reach_function(law)(v, distance, limits, floor)


@numba.njit(cache=True)
def reach_of(kind: int, ka: float, kj: float, v: float, d: float, cap: float, a: float,
             j: float, u1: float, f1: float, u2: float, f2: float) -> float:
    """g(v) in the kernels' terms (``law_code``; the block's length, speed cap,
    acceleration and jerk, and its floor ``floor_of``): the one implementation, for the
    compiled window and ``reach_function``."""
    f = capped_end_speed(kind, ka, kj, v, d, cap, a, j)
    if v < u1 and f1 < f:
        f = f1
    if v < u2 and f2 < f:
        f = f2
    return f


def reach_function(law: str) -> Callable[[float, float, Limits, ReachFloor], float]:
    """``monotone_end_speed`` for one law, as one closure ``reach(v, distance, limits,
    floor)`` (``reach_of`` without the law lookup; the look-ahead passes call it several
    times per block). A negative or NaN speed or distance is refused by
    ``max_end_speed`` (``PlanningError``)."""
    kind, ka, kj = law_code(law)

    def reach(v: float, distance: float, limits: Limits, floor: ReachFloor) -> float:
        if not (v >= 0.0 and distance >= 0.0):
            return max_end_speed(law, v, distance, limits)     # raises, naming them
        return reach_of(kind, ka, kj, v, distance, limits.max_velocity,
                        limits.max_acceleration, limits.max_jerk, *floor)
    return reach
