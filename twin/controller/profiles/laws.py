"""The acceleration laws: the shape of one speed change and its closed forms.

Every law changes the path speed from ``v0`` to ``v1`` in one *speed change* that starts and
ends at zero acceleration (the trapezoid excepted: its acceleration is a step). For the four
shape laws the change is a fixed normalised curve stretched over a duration ``T``:

    v(t) = v0 + Δv·φ(u),  a(t) = Δv·φ'(u)/T,  j(t) = Δv·φ''(u)/T²,  u = t/T ∈ [0, 1]

with φ(0) = 0, φ(1) = 1 and φ(u) + φ(1 − u) = 1 (point symmetry), so every change covers
``(v0 + v1)/2 · T`` of path. The limits fix the shortest ``T``: ``T ≥ k_a·|Δv|/A`` for the peak
acceleration ``k_a = max φ'`` and ``T ≥ sqrt(k_j·|Δv|/J)`` for the peak jerk
``k_j = max |φ''|``.

=============  =======================  ==========  ============  ===============================
law            φ(u)                     k_a         k_j           continuity of a(t), j(t)
=============  =======================  ==========  ============  ===============================
trapezoid      u                        1           (impulsive)   a jumps (the classic law)
parabolic      3u² − 2u³                3/2         6             a continuous; j jumps at ends
cosine         (1 − cos πu)/2           π/2         π²/2          a continuous; j jumps at ends
cubic          10u³ − 15u⁴ + 6u⁵        15/8        10/√3         a and j continuous (j = 0 ends)
=============  =======================  ==========  ============  ===============================

*parabolic* is seed 000's law: the acceleration is the parabola ``a_peak·4u(1 − u)``, zero at
both ends, with ``a_peak = 1.5·Δv/T`` and end jerk ``4·a_peak/T``. Its velocity, ``3u² − 2u³``,
is exactly the "cubic + quadratic" velocity diagram that seed 000 quotes from its ref. [5];
the two are one law. So that *cubic* is a distinct law, it is the next member of the same
family: the law whose **jerk is a cubic polynomial in time**, ``φ'' = 60u(1 − u)(1 − 2u)``,
zero at both ends. Its velocity is the quintic "smootherstep" and its acceleration
``30u²(1 − u)²`` is C¹, so neither acceleration nor jerk changes abruptly where a speed change
meets a cruise: it excites the least elastic oscillation of the four, at the price of a
longer change for the same peak acceleration (k_a = 1.875 against 1.5).

*jerk-limited* is the time-optimal seven-phase S-curve: jerk ±J or 0, acceleration a
trapezoid limited by A (a triangle when ``|Δv| < A²/J``). Its change takes
``|Δv|/A + A/J`` (or ``2·sqrt(|Δv|/J)``) and is point-symmetric too. ``plan_move`` computes its
moves with ruckig; the closed forms here serve the look-ahead planner.

``min_distance`` and ``max_end_speed`` are called per block by the planner: the closed forms
of `twin.controller.profiles.closed_forms`, compiled, floats only, no allocation.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

from twin.controller.profiles.closed_forms import (
    SCURVE_KIND,
    SHAPE_KIND,
    TRAPEZOID_KIND,
    peak_of,
    scurve_end_speed,
    scurve_time,
    shape_end_speed,
    shape_time,
)
from twin.controller.profiles.limits import Limits
from twin.errors import ConfigError, PlanningError

__all__ = [
    "JERK_LIMITED",
    "LAWS",
    "SHAPES",
    "Shape",
    "change_time",
    "check_law",
    "end_speed_function",
    "law_code",
    "max_end_speed",
    "min_distance",
    "peak_speed",
]

LAWS = ("trapezoid", "parabolic", "cosine", "cubic", "jerk-limited")
JERK_LIMITED = "jerk-limited"


class Shape:
    """A normalised speed change φ(u) on u ∈ [0, 1] (see the module docstring).

    Subclasses give φ and its integral and derivatives; each method takes ``u`` as a float
    or an ndarray and ``xp``, the module that evaluates transcendental functions on it
    (``math`` for floats, ``numpy`` for arrays).

    Attributes
    ----------
    name : str
        The law.
    peak_rate : float
        k_a = max φ'(u) (1): the peak acceleration is ``k_a·|Δv|/T``.
    peak_curvature : float
        k_j = max |φ''(u)| (1): the peak jerk is ``k_j·|Δv|/T²``; 0 when the law has no
        bounded jerk (the trapezoid).
    """

    name = ""
    peak_rate = 1.0
    peak_curvature = 0.0

    def integral(self, u, xp=math):
        """Φ(u) = ∫₀ᵘ φ, with Φ(1) = 1/2."""
        raise NotImplementedError

    def velocity(self, u, xp=math):
        """φ(u), from 0 to 1."""
        raise NotImplementedError

    def acceleration(self, u, xp=math):
        """φ'(u)."""
        raise NotImplementedError

    def jerk(self, u, xp=math):
        """φ''(u)."""
        raise NotImplementedError


class _Linear(Shape):
    name = "trapezoid"
    peak_rate = 1.0
    peak_curvature = 0.0

    def integral(self, u, xp=math):
        return 0.5 * u * u

    def velocity(self, u, xp=math):
        return u

    def acceleration(self, u, xp=math):
        return 1.0 + 0.0 * u

    def jerk(self, u, xp=math):
        return 0.0 * u


class _Parabolic(Shape):
    name = "parabolic"
    peak_rate = 1.5
    peak_curvature = 6.0

    def integral(self, u, xp=math):
        return u * u * u * (1.0 - 0.5 * u)

    def velocity(self, u, xp=math):
        return u * u * (3.0 - 2.0 * u)

    def acceleration(self, u, xp=math):
        return 6.0 * u * (1.0 - u)

    def jerk(self, u, xp=math):
        return 6.0 - 12.0 * u


class _Cosine(Shape):
    name = "cosine"
    peak_rate = 0.5 * math.pi
    peak_curvature = 0.5 * math.pi**2

    def integral(self, u, xp=math):
        return 0.5 * u - xp.sin(math.pi * u) / (2.0 * math.pi)

    def velocity(self, u, xp=math):
        return 0.5 - 0.5 * xp.cos(math.pi * u)

    def acceleration(self, u, xp=math):
        return 0.5 * math.pi * xp.sin(math.pi * u)

    def jerk(self, u, xp=math):
        return 0.5 * math.pi**2 * xp.cos(math.pi * u)


class _Smootherstep(Shape):
    name = "cubic"
    peak_rate = 15.0 / 8.0                    # 30u²(1-u)² at u = 1/2
    peak_curvature = 10.0 / math.sqrt(3.0)    # |60u(1-u)(1-2u)| at u = 1/2 ± 1/(2√3)

    def integral(self, u, xp=math):
        return u * u * u * u * (2.5 + u * (u - 3.0))

    def velocity(self, u, xp=math):
        return u * u * u * (10.0 + u * (6.0 * u - 15.0))

    def acceleration(self, u, xp=math):
        w = u * (1.0 - u)
        return 30.0 * w * w

    def jerk(self, u, xp=math):
        return 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)


SHAPES: dict[str, Shape] = {s.name: s for s in (_Linear(), _Parabolic(), _Cosine(),
                                                _Smootherstep())}
"""The shape of each law but the jerk-limited one, by law name."""


# ----------------------------------------------------------------------------- closed forms
# A change of |Δv| = dv takes time(dv, A, J); from v0 the highest speed after d of path is
# end_speed(v0, d, A, J): the compiled closed forms (`closed_forms`), bound to each law.
_TIME: dict[str, Callable[[float, float, float], float]] = {
    name: partial(shape_time, s.peak_rate, s.peak_curvature) for name, s in SHAPES.items()}
_TIME[JERK_LIMITED] = scurve_time
_END_SPEED: dict[str, Callable[[float, float, float, float], float]] = {
    name: partial(shape_end_speed, s.peak_rate, s.peak_curvature) for name, s in SHAPES.items()}
_END_SPEED[JERK_LIMITED] = scurve_end_speed


_CODES = {name: (TRAPEZOID_KIND if name == "trapezoid" else SHAPE_KIND, s.peak_rate,
                 s.peak_curvature) for name, s in SHAPES.items()}
_CODES[JERK_LIMITED] = (SCURVE_KIND, 0.0, 0.0)


def law_code(law: str) -> tuple[int, float, float]:
    """(kind, k_a, k_j) of a law for the compiled closed forms (`closed_forms`): the
    trapezoid, a shape law (its peak rate and curvature, `SHAPES`), or the jerk-limited
    S-curve."""
    code = _CODES.get(law)
    if code is None:
        check_law(law)
    return code


def check_law(law: str) -> None:
    """Raise ``ConfigError("law", ...)`` unless ``law`` is one of `LAWS`."""
    if law not in _TIME:
        raise ConfigError("law", f"unknown acceleration law {law!r}; expected one of "
                          f"{', '.join(LAWS)}")


def change_time(law: str, dv: float, limits: Limits) -> float:
    """Shortest duration of one speed change of magnitude ``dv`` (s).

    Parameters
    ----------
    law : str
        One of `LAWS`.
    dv : float
        |v1 − v0| (m/s), ≥ 0.
    limits : Limits
        Acceleration (m/s²) and jerk (m/s³) limits.
    """
    fn = _TIME.get(law)
    if fn is None:
        check_law(law)
    return fn(dv, limits.max_acceleration, limits.max_jerk)


def min_distance(law: str, v_start: float, v_end: float, limits: Limits) -> float:
    """Shortest path to change speed from ``v_start`` to ``v_end`` (m).

    One speed change of the law at its limits; it covers ``(v_start + v_end)/2 · T`` with
    ``T = change_time(law, |v_end − v_start|, limits)``. Symmetric in the two speeds.

    Parameters
    ----------
    law : str
        One of `LAWS`.
    v_start, v_end : float
        Speeds (m/s), ≥ 0.
    limits : Limits
        Path limits; ``max_velocity`` is not used.

    Raises
    ------
    PlanningError
        If a speed is negative or NaN. ``ConfigError`` for an unknown law.
    """
    fn = _TIME.get(law)
    if fn is None:
        check_law(law)
    if not (v_start >= 0.0 and v_end >= 0.0):
        raise PlanningError(f"speeds must be >= 0, got v_start={v_start!r}, v_end={v_end!r}")
    dv = v_end - v_start if v_end >= v_start else v_start - v_end
    return 0.5 * (v_start + v_end) * fn(dv, limits.max_acceleration, limits.max_jerk)


def end_speed_function(law: str) -> Callable[[float, float, float, float], float]:
    """The law's uncapped end speed ``f(v_start, distance, A, J)`` (m/s), for callers that
    call it per block and check their arguments themselves (the planner's passes);
    `max_end_speed` is it with the checks and the speed cap."""
    fn = _END_SPEED.get(law)
    if fn is None:
        check_law(law)
    return fn


def max_end_speed(law: str, v_start: float, distance: float, limits: Limits) -> float:
    """Highest speed reachable after ``distance`` of path starting at ``v_start`` (m/s).

    The inverse of `min_distance` in its second argument, capped at ``limits.max_velocity``:
    ``min_distance(law, v_start, max_end_speed(...), limits) == distance`` unless capped.
    Because a speed change and its time reverse cover the same path, the braking relation is
    the same function: the highest speed from which the path can brake to ``v_end`` within
    ``distance`` is ``max_end_speed(law, v_end, distance, limits)``.

    Parameters
    ----------
    law : str
        One of `LAWS`.
    v_start : float
        Speed at the start (m/s), 0 ≤ v_start ≤ ``limits.max_velocity``.
    distance : float
        Path length available (m), ≥ 0.
    limits : Limits
        Path limits.

    Raises
    ------
    PlanningError
        If ``v_start`` or ``distance`` is negative or NaN. ``ConfigError`` for an unknown law.
    """
    fn = _END_SPEED.get(law)
    if fn is None:
        check_law(law)
    if not (v_start >= 0.0 and distance >= 0.0):
        raise PlanningError(
            f"need v_start >= 0 and distance >= 0, got v_start={v_start!r}, "
            f"distance={distance!r}")
    v = fn(v_start, distance, limits.max_acceleration, limits.max_jerk)
    cap = limits.max_velocity
    return v if v < cap else cap


def peak_speed(law: str, distance: float, v_start: float, v_end: float, cap: float,
               limits: Limits) -> float:
    """Highest cruise speed of a move (m/s): the largest v ≤ ``cap`` whose change up from
    ``v_start`` and down to ``v_end`` fit in ``distance``.

    The path of the two changes grows monotonically with v, so the root is bracketed
    between ``max(v_start, v_end)`` and the lower of ``cap`` and the speed that the change
    from ``max(v_start, v_end)`` alone reaches in ``distance``; the Illinois (modified regula
    falsi) method finds it; the answer errs on the low side, so the cruise length it leaves is ≥ 0.

    Parameters
    ----------
    law : str
        One of `LAWS`.
    distance : float
        Path length (m), at least ``min_distance(law, v_start, v_end, limits)``.
    v_start, v_end : float
        Speeds at the ends (m/s), ≤ ``cap``.
    cap : float
        Highest speed allowed (m/s).
    limits : Limits
        Path limits.
    """
    kind, ka, kj = law_code(law)
    return peak_of(kind, ka, kj, float(distance), float(v_start), float(v_end), float(cap),
                   limits.max_velocity, limits.max_acceleration, limits.max_jerk)
