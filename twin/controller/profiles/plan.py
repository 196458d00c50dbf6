"""Plan one 1-D move: accelerate, cruise, brake, under any acceleration law."""

from __future__ import annotations

import math

from twin.controller.profiles.laws import (
    JERK_LIMITED,
    SHAPES,
    change_time,
    check_law,
    max_end_speed,
    min_distance,
    peak_speed,
)
from twin.controller.profiles.limits import Limits
from twin.controller.profiles.profile import Blend, Polynomial, Profile, Segment
from twin.controller.profiles.scurve import (
    direct_phases,
    integrate_phases,
    jerk_limited_segments,
)
from twin.errors import PlanningError

__all__ = ["TOLERANCE", "plan_move"]

TOLERANCE = 1e-9
"""Relative slack on speeds (1) that absorbs the rounding of a caller's arithmetic: a speed
this much above the cap or above the reachable one is taken as equal to it."""


def plan_move(law: str, distance: float, *, v_start: float, v_end: float, v_max: float,
              limits: Limits) -> Profile:
    """Plan a move of exactly ``distance`` from ``v_start`` to ``v_end``.

    The move accelerates to the highest cruise speed that fits, at most
    ``min(v_max, limits.max_velocity)``, cruises, and brakes to ``v_end``; when the distance
    is short the peak drops below the cap and the cruise vanishes; when it is just the
    shortest path between the two speeds, the move is a single speed change.

    Parameters
    ----------
    law : str
        One of `LAWS`.
    distance : float
        Path length (m), ≥ 0.
    v_start, v_end : float
        Speeds at the ends (m/s), 0 ≤ v ≤ the cap; either may be the larger.
    v_max : float
        Cruise speed wanted (m/s), ≥ 0; ``limits.max_velocity`` caps it.
    limits : Limits
        Path limits.

    Returns
    -------
    Profile

    Raises
    ------
    PlanningError
        Naming the numbers: a speed above the cap, ``v_end`` not reachable from ``v_start``
        within ``distance``, a negative or non-finite input.
    ConfigError
        For an unknown law.
    """
    check_law(law)
    for name, value in (("distance", distance), ("v_start", v_start), ("v_end", v_end),
                        ("v_max", v_max)):
        if not (math.isfinite(value) and value >= 0.0):
            raise PlanningError(f"{name} must be finite and >= 0, got {value!r}")
    cap = min(v_max, limits.max_velocity)
    v_start = _within(cap, "v_start", v_start)
    v_end = _within(cap, "v_end", v_end)
    low, high = min(v_start, v_end), max(v_start, v_end)
    reachable = max_end_speed(law, low, distance, limits)
    if high > reachable * (1.0 + TOLERANCE):
        raise PlanningError(
            f"{law}: cannot change speed from {v_start!r} to {v_end!r} m/s within "
            f"{distance!r} m: that needs {min_distance(law, v_start, v_end, limits)!r} m "
            f"(reachable within {distance!r} m: {reachable!r} m/s)")
    if distance <= min_distance(law, v_start, v_end, limits) * (1.0 + TOLERANCE):
        return _single_change(law, distance, v_start, v_end, limits)
    if cap <= 0.0:
        raise PlanningError(f"cannot move {distance!r} m with a speed cap of {cap!r} m/s")
    if law == JERK_LIMITED:
        segments = jerk_limited_segments(distance, v_start, v_end, cap, limits)
        return Profile(law, distance, v_start, v_end,
                       max(seg.speed_range()[1] for seg in segments), tuple(segments))
    peak = peak_speed(law, distance, v_start, v_end, cap, limits)
    return Profile(law, distance, v_start, v_end, peak,
                   tuple(_shape_segments(law, distance, v_start, peak, v_end, limits)))


def _within(cap: float, name: str, value: float) -> float:
    if value > cap:
        if value > cap * (1.0 + TOLERANCE):
            raise PlanningError(f"{name}={value!r} m/s is above the speed cap {cap!r} m/s")
        return cap
    return value


def _single_change(law: str, distance: float, v_start: float, v_end: float,
                   limits: Limits) -> Profile:
    """One speed change over exactly ``distance`` (its shortest path, to rounding)."""
    peak = max(v_start, v_end)
    duration = 2.0 * distance / (v_start + v_end) if distance > 0.0 else 0.0
    if duration <= 0.0:             # nothing moves; the speeds agree to TOLERANCE
        return Profile(law, distance, v_start, v_end, peak, ())
    segments: list[Segment]
    if law == JERK_LIMITED:
        segments = integrate_phases(direct_phases(v_start, v_end, duration, limits.max_jerk),
                                    v_start, distance=distance)
    else:
        segments = [Blend(0.0, duration, 0.0, v_start, v_end - v_start, SHAPES[law])]
    return Profile(law, distance, v_start, v_end, peak, tuple(segments))


def _shape_segments(law: str, distance: float, v_start: float, peak: float, v_end: float,
                    limits: Limits) -> list[Segment]:
    shape = SHAPES[law]
    t_up = change_time(law, peak - v_start, limits)
    t_down = change_time(law, peak - v_end, limits)
    d_up = 0.5 * (v_start + peak) * t_up
    d_down = 0.5 * (peak + v_end) * t_down
    cruise = distance - d_up - d_down
    segments: list[Segment] = []
    t = s = 0.0
    if t_up > 0.0:
        segments.append(Blend(t, t_up, s, v_start, peak - v_start, shape))
        t, s = t_up, segments[-1].end()[0]
    if cruise > 0.0 and peak > 0.0:
        segments.append(Polynomial(t, cruise / peak, s, peak, 0.0, 0.0))
        t, s = t + cruise / peak, segments[-1].end()[0]
    if t_down > 0.0:
        segments.append(Blend(t, t_down, s, peak, v_end - peak, shape))
    return segments
