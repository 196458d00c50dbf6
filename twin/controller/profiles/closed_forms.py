"""The acceleration laws' closed forms, compiled: the one implementation of a speed change's
duration (``time_of``), its path (``distance_of``), the end speed a path allows
(``end_speed``) and a move's peak speed (``peak_of``), for the Python callers
(`twin.controller.profiles.laws`) and the compiled ones (the look-ahead window,
`twin.controller.window`, and `twin.controller.reach`) alike.

A law enters as its ``law_code`` (`twin.controller.profiles.laws`): its kind
(``TRAPEZOID_KIND``, ``SHAPE_KIND``, ``SCURVE_KIND``) and, for a shape law, its peak rate
``k_a`` and peak curvature ``k_j``. Every function is float-only and allocation-free.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["SCURVE_KIND", "SHAPE_KIND", "TRAPEZOID_KIND", "capped_end_speed", "cubic_root",
           "distance_of", "end_speed", "peak_of", "scurve_end_speed", "scurve_time",
           "shape_end_speed", "shape_time", "time_of"]

@numba.njit(cache=True)
def shape_time(ka: float, kj: float, dv: float, a: float, j: float) -> float:
    """Duration of a change |Δv| = ``dv`` of a shape law (peak rate ``ka``, peak curvature
    ``kj``): the longer of its acceleration- and jerk-limited times."""
    ta = ka * dv / a
    if kj == 0.0:
        return ta
    tj = math.sqrt(kj * dv / j)
    return ta if ta >= tj else tj


@numba.njit(cache=True)
def scurve_time(dv: float, a: float, j: float) -> float:
    """Duration of a change |Δv| = ``dv`` of the jerk-limited S-curve."""
    if dv * j >= a * a:                       # acceleration reaches A: a trapezoid
        return dv / a + a / j
    return 2.0 * math.sqrt(dv / j)            # acceleration a triangle


@numba.njit(cache=True)
def cubic_root(p: float, q: float) -> float:
    """The real root of x³ + p·x = q for p ≥ 0, q ≥ 0, in closed form (one Newton polish)."""
    if q <= 0.0:
        return 0.0
    scale = (p / 3.0) ** 1.5
    if scale > 1e-100 * q:                    # hyperbolic form: no cancellation for any p
        x = 2.0 * math.sqrt(p / 3.0) * math.sinh(math.asinh(0.5 * q / scale) / 3.0)
    else:                                     # p·x negligible against x³
        x = np.cbrt(q)
    return x - (x * (x * x + p) - q) / (3.0 * x * x + p)


@numba.njit(cache=True)
def shape_end_speed(ka: float, kj: float, v0: float, d: float, a: float, j: float) -> float:
    """End speed of a shape law (peak rate ``ka``, peak curvature ``kj``).

    Acceleration-limited change: d = ka·(v1² − v0²)/(2A). Jerk-limited change (dv below
    dv* = kj·A²/(ka²·J)): d = (2·v0 + x²)/2 · x·sqrt(kj/J) with x = sqrt(dv), a cubic in x.
    """
    if kj != 0.0:
        dv_star = kj * a * a / (ka * ka * j)
        if d < (v0 + 0.5 * dv_star) * ka * dv_star / a:
            x = cubic_root(2.0 * v0, 2.0 * d * math.sqrt(j / kj))
            return v0 + x * x
    return math.sqrt(v0 * v0 + 2.0 * a * d / ka)


@numba.njit(cache=True)
def scurve_end_speed(v0: float, d: float, a: float, j: float) -> float:
    """End speed of the jerk-limited S-curve."""
    dv_star = a * a / j
    if d >= (v0 + 0.5 * dv_star) * 2.0 * a / j:
        # d = (v0 + dv/2)·(dv/A + A/J): a quadratic in dv, solved without cancellation.
        b = v0 / a + 0.5 * a / j
        c = v0 * a / j - d                    # < 0 in this branch
        return v0 - 2.0 * c / (b + math.sqrt(b * b - 2.0 * c / a))
    x = cubic_root(2.0 * v0, d * math.sqrt(j))   # d = (2·v0 + x²)·x/sqrt(J)
    return v0 + x * x


TRAPEZOID_KIND, SHAPE_KIND, SCURVE_KIND = 0, 1, 2
"""The kinds of law the compiled kernels tell apart (``law_code``)."""


@numba.njit(cache=True)
def end_speed(kind: int, ka: float, kj: float, v0: float, d: float, a: float,
              j: float) -> float:
    """The uncapped end speed of the law ``law_code`` gives (kind, ka, kj): the one
    implementation of the closed forms, for the Python and the compiled callers alike."""
    if kind == SCURVE_KIND:
        return scurve_end_speed(v0, d, a, j)
    return shape_end_speed(ka, kj, v0, d, a, j)


@numba.njit(cache=True, inline="always")
def capped_end_speed(kind: int, ka: float, kj: float, v0: float, d: float, cap: float,
                     a: float, j: float) -> float:
    """``end_speed`` capped at ``cap``: `max_end_speed` for arguments known valid."""
    v = end_speed(kind, ka, kj, v0, d, a, j)
    return v if v < cap else cap


@numba.njit(cache=True)
def time_of(kind: int, ka: float, kj: float, dv: float, a: float, j: float) -> float:
    """``change_time`` in the kernels' terms (``law_code``)."""
    if kind == SCURVE_KIND:
        return scurve_time(dv, a, j)
    return shape_time(ka, kj, dv, a, j)


@numba.njit(cache=True, inline="always")
def distance_of(kind: int, ka: float, kj: float, v0: float, v1: float, a: float,
                j: float) -> float:
    """``min_distance`` in the kernels' terms, for speeds known valid."""
    dv = v1 - v0 if v1 >= v0 else v0 - v1
    return 0.5 * (v0 + v1) * time_of(kind, ka, kj, dv, a, j)


@numba.njit(cache=True)
def peak_of(kind: int, ka: float, kj: float, distance: float, v_start: float, v_end: float,
            cap: float, v_max: float, a: float, j: float) -> float:
    """``peak_speed`` in the kernels' terms (``v_max``: the limits' speed cap)."""
    lo = max(v_start, v_end)
    reach = end_speed(kind, ka, kj, lo, distance, a, j)
    hi = min(cap, reach if reach < v_max else v_max)       # one change alone fits
    g_lo = (distance_of(kind, ka, kj, v_start, lo, a, j)
            + distance_of(kind, ka, kj, lo, v_end, a, j) - distance)
    g_hi = (distance_of(kind, ka, kj, v_start, hi, a, j)
            + distance_of(kind, ka, kj, hi, v_end, a, j) - distance)
    if g_hi <= 0.0:
        return hi
    w_lo, w_hi = g_lo, g_hi         # Illinois weights: the values, halved on a stale side
    side = 0
    for _ in range(200):
        if hi - lo <= 4.0 * np.spacing(hi) or -g_lo <= 1e-15 * distance:
            break
        v = hi - w_hi * (hi - lo) / (w_hi - w_lo)
        if not lo < v < hi:
            v = 0.5 * (lo + hi)
        g = (distance_of(kind, ka, kj, v_start, v, a, j)
             + distance_of(kind, ka, kj, v, v_end, a, j) - distance)
        if g <= 0.0:
            lo, g_lo, w_lo = v, g, g
            if side < 0:
                w_hi *= 0.5
            side = -1
        else:
            hi, g_hi, w_hi = v, g, g
            if side > 0:
                w_lo *= 0.5
            side = 1
    return lo
