"""The jerk-limited (seven-phase S-curve) move, computed by ruckig.

The 1-D move maps onto ruckig's single-degree-of-freedom problem: position 0 → ``distance``,
velocity ``v_start`` → ``v_end``, acceleration 0 → 0, with ``max_velocity`` = the cruise cap,
``min_velocity`` = 0 (the path never reverses), ``max_acceleration`` = A, ``max_jerk`` = J.
Ruckig's time-optimal answer is the accelerate-cruise-brake move with the highest cruise
speed that fits. Its seven phases (duration, jerk) are re-integrated here in float64 into
`Polynomial` segments, so that evaluating the move costs a few multiplications, and the
cruise absorbs the last rounding of the end position.

Ruckig accepts a candidate profile by absolute tolerances (1e-8 on the end position and
speed, 1e-10 on the end acceleration: ``ruckig/profile.hpp``), while the moves of a machine
tool span 1e-9 to 1 m and 1e-4 to 1 m/s. So ruckig gets the problem in units that
make it O(1): speed unit = an upper bound of the peak speed, time unit = the S-curve change
from rest to it, and a long cruise at the cap shortened to one length unit (the cruise phase
is stretched back afterwards). Two edges never reach ruckig: a move that only just fits (a
single speed change over its shortest path, `direct_phases`), and any answer of ruckig that
fails the check of end state and limits; both are built by `closed_form_phases`, the same
seven phases from the closed forms of `twin.controller.profiles.laws`. The tests hold the
two constructions against each other.
"""

from __future__ import annotations

import math

from ruckig import InputParameter, Result, Ruckig, RuckigError, Trajectory

from twin.controller.profiles.laws import (
    JERK_LIMITED,
    change_time,
    max_end_speed,
    min_distance,
    peak_speed,
)
from twin.controller.profiles.limits import Limits
from twin.controller.profiles.profile import Polynomial, constant_jerk

__all__ = [
    "CRUISE_PHASE",
    "closed_form_phases",
    "direct_phases",
    "integrate_phases",
    "jerk_limited_segments",
    "ruckig_phases",
    "ruckig_segments",
]

CRUISE_PHASE = 3
"""Index of the cruise among the seven phases (jerk +, 0, −, cruise, −, 0, +)."""

_OK = (Result.Working, Result.Finished)
_CHECK = 1e-9       # relative slack of the check of ruckig's answer


def direct_phases(v_start: float, v_end: float, duration: float,
                  max_jerk: float) -> list[tuple[float, float]]:
    """One S-curve speed change from ``v_start`` to ``v_end`` taking exactly ``duration``.

    The acceleration is a symmetric trapezoid with jerk ``max_jerk`` on its flanks; its
    height follows from the duration (``T = |Δv|/a_p + a_p/J``). A duration a rounding error
    shorter than the triangle's ``2·sqrt(|Δv|/J)`` gets a triangle with jerk ``4·|Δv|/T²``.

    Parameters
    ----------
    v_start, v_end : float
        Speeds (m/s).
    duration : float
        Duration of the change (s), ≥ 0.
    max_jerk : float
        Jerk of the flanks (m/s³).

    Returns
    -------
    list of (duration, jerk)
        The three phases: s and m/s³.
    """
    dv = abs(v_end - v_start)
    if dv == 0.0 or duration <= 0.0:
        return [(0.0, 0.0)] * 3
    sign = 1.0 if v_end > v_start else -1.0
    T = duration
    root = T * T - 4.0 * dv / max_jerk
    if root >= 0.0:
        peak = 2.0 * dv / (T + math.sqrt(root))      # the smaller root, without cancellation
        ramp, jerk = peak / max_jerk, max_jerk
    else:
        ramp, jerk = 0.5 * T, 4.0 * dv / (T * T)
    hold = max(T - 2.0 * ramp, 0.0)
    return [(ramp, sign * jerk), (hold, 0.0), (ramp, -sign * jerk)]


def closed_form_phases(distance: float, v_start: float, v_end: float, cap: float,
                       limits: Limits) -> list[tuple[float, float]]:
    """The time-optimal jerk-limited move from the closed forms (no ruckig).

    Parameters are those of `ruckig_phases`; so is the result: seven (duration, jerk)
    phases, s and m/s³, the fourth the cruise.
    """
    peak = peak_speed(JERK_LIMITED, distance, v_start, v_end, cap, limits)
    cruise = (distance - min_distance(JERK_LIMITED, v_start, peak, limits)
              - min_distance(JERK_LIMITED, peak, v_end, limits))
    up = change_time(JERK_LIMITED, peak - v_start, limits)
    down = change_time(JERK_LIMITED, peak - v_end, limits)
    hold = max(cruise, 0.0) / peak if peak > 0.0 else 0.0
    return [*direct_phases(v_start, peak, up, limits.max_jerk), (hold, 0.0),
            *direct_phases(peak, v_end, down, limits.max_jerk)]


def ruckig_phases(distance: float, v_start: float, v_end: float, cap: float,
                  limits: Limits) -> list[tuple[float, float]] | None:
    """The time-optimal jerk-limited move, from ruckig's offline ``calculate``.

    Parameters
    ----------
    distance : float
        Path length (m), more than ``min_distance(v_start, v_end)``.
    v_start, v_end : float
        Speeds at the ends (m/s), within ``[0, cap]``.
    cap : float
        Highest cruise speed (m/s), > 0.
    limits : Limits
        Acceleration (m/s²) and jerk (m/s³) limits.

    Returns
    -------
    list of (duration, jerk) or None
        Ruckig's seven phases in SI (s, m/s³); the cruise phase may be short of the full
        ``distance`` (`integrate_phases` stretches it). None if ruckig reports an error or
        its own end position misses the target by more than 1e-9 relative.
    """
    speed_unit = min(cap, max_end_speed(JERK_LIMITED, max(v_start, v_end), distance, limits))
    time_unit = change_time(JERK_LIMITED, speed_unit, limits)
    length_unit = speed_unit * time_unit
    target = distance
    at_cap = min_distance(JERK_LIMITED, v_start, cap, limits) + min_distance(
        JERK_LIMITED, cap, v_end, limits)
    if at_cap < distance:
        target = min(distance, at_cap + length_unit)
    inp = InputParameter(1)
    inp.current_position = [0.0]
    inp.current_velocity = [v_start / speed_unit]
    inp.current_acceleration = [0.0]
    inp.target_position = [target / length_unit]
    inp.target_velocity = [v_end / speed_unit]
    inp.target_acceleration = [0.0]
    inp.max_velocity = [cap / speed_unit]
    inp.min_velocity = [0.0]
    inp.max_acceleration = [limits.max_acceleration * time_unit / speed_unit]
    inp.max_jerk = [limits.max_jerk * time_unit * time_unit / speed_unit]
    trajectory = Trajectory(1)
    try:
        result = Ruckig(1).calculate(inp, trajectory)
    except RuckigError:
        return None
    profile = trajectory.profiles[0][0]
    if result not in _OK or abs(profile.p[-1] - target / length_unit) > _CHECK * profile.p[-1]:
        return None
    jerk_unit = length_unit / time_unit**3
    return [(t * time_unit, j * jerk_unit) for t, j in zip(profile.t, profile.j, strict=True)]


def jerk_limited_segments(distance: float, v_start: float, v_end: float, cap: float,
                          limits: Limits) -> list[Polynomial]:
    """The jerk-limited move as segments: ruckig's if it passes the check, else the closed
    form's. Parameters are those of `ruckig_phases`."""
    segments = ruckig_segments(distance, v_start, v_end, cap, limits)
    if segments is None:
        segments = integrate_phases(closed_form_phases(distance, v_start, v_end, cap, limits),
                                    v_start, distance=distance, cruise=CRUISE_PHASE)
    return segments


def ruckig_segments(distance: float, v_start: float, v_end: float, cap: float,
                    limits: Limits) -> list[Polynomial] | None:
    """Ruckig's move as segments, or None if ruckig fails or its answer misses the end state
    or the limits by more than rounding. Parameters are those of `ruckig_phases`."""
    phases = ruckig_phases(distance, v_start, v_end, cap, limits)
    if phases is None:
        return None
    segments = integrate_phases(phases, v_start, distance=distance, cruise=CRUISE_PHASE)
    return segments if _plausible(segments, distance, v_end, cap, limits) else None


def _plausible(segments: list[Polynomial], distance: float, v_end: float, cap: float,
               limits: Limits) -> bool:
    """Does the move end where it should and keep within the limits (to rounding)?"""
    if not segments:
        return False
    s, v, a = segments[-1].end()
    if not (abs(s - distance) <= 1e-12 * distance and abs(v - v_end) <= _CHECK * cap
            and abs(a) <= _CHECK * limits.max_acceleration):
        return False
    top_a, top_j = limits.max_acceleration * (1 + _CHECK), limits.max_jerk * (1 + _CHECK)
    for seg in segments:
        low, high = seg.speed_range()
        if not (math.isfinite(seg.duration) and abs(seg.j) <= top_j and abs(seg.a0) <= top_a
                and low >= -_CHECK * cap and high <= cap * (1 + _CHECK)):
            return False
    return True


def integrate_phases(phases: list[tuple[float, float]], v_start: float, *,
                     distance: float | None = None, cruise: int | None = None
                     ) -> list[Polynomial]:
    """Chain constant-jerk phases into `Polynomial` segments, starting at zero acceleration.

    Parameters
    ----------
    phases : list of (duration, jerk)
        Durations (s) and jerks (m/s³); empty phases are dropped.
    v_start : float
        Speed at the start (m/s).
    distance : float, optional
        Path length the phases must cover (m). The phase ``cruise`` (zero jerk, positive
        speed) is lengthened or shortened to land on it; without one, time is stretched by
        ``k = distance/end`` (durations × k, jerks / k²), which keeps every speed and moves
        the limits by the same rounding-sized factor.
    cruise : int, optional
        Index into ``phases`` of the cruise.
    """
    if distance is not None:
        phases = _land(phases, v_start, distance, cruise)
    segments: list[Polynomial] = []
    t = s = a = 0.0
    v = v_start
    for length, jerk in phases:
        if length > 0.0:
            segments.append(Polynomial(t, length, s, v, a, jerk))
            s, v, a = constant_jerk(length, s, v, a, jerk)
            t += length
    return segments


def _land(phases: list[tuple[float, float]], v_start: float, distance: float,
          cruise: int | None) -> list[tuple[float, float]]:
    """The phases, adjusted so that they end exactly at ``distance`` (see `integrate_phases`)."""
    s = a = 0.0
    v = v_start
    cruise_speed = 0.0
    for index, (length, jerk) in enumerate(phases):
        if index == cruise:
            cruise_speed = v
        if length > 0.0:
            s, v, a = constant_jerk(length, s, v, a, jerk)
    if s == distance or s <= 0.0:
        return phases
    fixed = list(phases)
    if cruise is not None and fixed[cruise][0] > 0.0 and fixed[cruise][1] == 0.0 \
            and cruise_speed > 0.0:
        fixed[cruise] = (max(fixed[cruise][0] + (distance - s) / cruise_speed, 0.0), 0.0)
        return fixed
    k = distance / s
    return [(length * k, jerk / (k * k)) for length, jerk in fixed]
