"""The fit's last stage: every replayed parameter together, its profile intervals, and the
decision of what the data cannot separate.

1. Least squares on all the coordinates at once (``lsq.solve``), then each coordinate's
   profile interval (``profile.profile``). A profile point below the optimum means the
   optimum was not one: the fit is run again from there (once).
2. A coordinate whose interval is open or wider than ``TOLERANCE`` is not identifiable
   from these experiments. They usually come in groups that trade off (below the current
   limit the inertia, the friction and the speed regulator's gain scale together; the
   speed steps see only their ratios). The first of the group in ``ANCHORS`` order is held
   at BASE's value (or, where the data reject BASE's value, at the nearest end of its
   interval), the others are fitted again around it, and those of the group whose profile
   then closes are reported as identified *given* the one held: their values are right
   relative to it, and they are flagged not identifiable on their own. This repeats while
   a group remains; then any value the holds moved out of its interval, or by more than
   half its half-interval, is flagged the same way (it depends on what was held), and so
   is any value a held one would move by more than its own half-interval anywhere within
   the held one's reach (to first order, the optimum's Jacobian with the others
   re-fitted): seen over Modbus, a speed gain 12 % off inside a tight interval, moved
   there by the integral time held at BASE's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from twin.identify.lsq import BOUNDS, Solution, coordinate, solve, with_coordinate
from twin.identify.profile import QUANTITY, Profile, own_coordinate, profile, systematic_variance
from twin.identify.replay import AxisParams, Problem

__all__ = ["ANCHORS", "TOLERANCE", "Joint", "joint_fit"]

TOLERANCE = {"inertia": math.log(1.25), "coulomb": math.log(1.25),
             "viscous": math.log(1.5), "breakaway": 0.5, "backlash": 3e-6,
             "resistance": math.log(1.25), "inductance": math.log(1.25),
             "speed_kp": math.log(1.25), "speed_ti": math.log(1.25),
             "reference_filter": math.log(1.5), "current_kp": math.log(1.5),
             "current_ti": math.log(1.5), "brush_drop": 1.0}
"""Largest 95 % half-interval (in the fitted coordinate: log for the multiplicative ones,
1 for the break-away ratio, m for the lost motion, V for the brush drop) of a parameter
called identifiable."""

ANCHORS = ("inertia", "resistance", "inductance", "current_kp", "current_ti", "brush_drop",
           "viscous", "breakaway", "reference_filter", "speed_ti", "coulomb", "speed_kp")
"""The order in which a group of parameters that trade off gets one held at BASE's value:
the inertia first (below the current limit it scales with the friction and the speed
gain, which then stay right relative to it)."""

ROUNDS = 1
"""Groups held one at a time (each round a fit and the remaining profiles); what is left
after them is held all at once, with one more fit."""


@dataclass
class Joint:
    """The outcome of ``joint_fit``, per axis.

    Attributes
    ----------
    params : dict of str to AxisParams
    intervals : dict of str to dict of str to tuple of float
        (low, high) in the coordinate (NaN: open).
    held : dict of str to dict of str to str
        The parameters held, and how: ``"base"`` (BASE's value) or ``"bound"`` (the end of
        the interval nearest to BASE's value, which the data reject).
    given : dict of str to dict of str to tuple of str
        The parameters identified only given the held ones.
    linear : dict of str to dict of str to float
        The linearised half-interval at the optimum (what the Jacobian alone says).
    restarts : int
        Fits run again from a profile point below the optimum.
    misfit : dict of str to float
        The systematic part of each axis' residual variance after the first least squares
        (``profile.systematic_variance``).
    profiled : bool
        False where ``unprofiled`` said so after the first least squares: no profile was
        taken (the intervals are NaN, nothing is held).
    """

    params: dict[str, AxisParams]
    intervals: dict[str, dict[str, tuple[float, float]]]
    held: dict[str, dict[str, str]] = field(default_factory=dict)
    given: dict[str, dict[str, tuple[str, ...]]] = field(default_factory=dict)
    linear: dict[str, dict[str, float]] = field(default_factory=dict)
    restarts: int = 0
    misfit: dict[str, float] = field(default_factory=dict)
    profiled: bool = True


def _wide(name: str, prof: Profile, x: float) -> bool:
    if prof.open:
        return True
    return max(x - prof.low, prof.high - x) > TOLERANCE[name]


def _reach(names: Sequence[str]) -> dict[str, float]:
    return {n: 2.0 * TOLERANCE[n] for n in names}


def joint_fit(problem: Problem, params: dict[str, AxisParams], names: Sequence[str],
              mask: np.ndarray, start: dict[str, AxisParams], *, max_nfev: int = 2,
              unprofiled: Callable[[Solution], bool] | None = None) -> Joint:
    """Fit the quantities ``names`` together on the ticks of ``mask`` (in the coordinates
    ``profile.own_coordinate`` gives them), profile them and hold what the data cannot
    separate (see the module docstring). Intervals are in ``lsq.coordinate`` units.

    ``unprofiled``: where it says so of the first least squares' solution (the caller will
    keep BASE's values for every axis there), that solution is returned without a profile
    (``Joint.profiled`` False): the profiles, most of this stage's replays, would be thrown
    away."""
    names = list(names)
    coords = [own_coordinate(n) for n in names]
    axes = problem.axes
    sol = solve(problem, params, coords, mask, start, max_nfev=max_nfev)
    smooth = {a: systematic_variance(sol.res[a]) for a in axes}
    if unprofiled is not None and unprofiled(sol):
        none = {a: {n: (math.nan, math.nan) for n in names} for a in axes}
        return Joint(dict(sol.params), none, {a: {} for a in axes}, {a: {} for a in axes},
                     {a: {n: math.nan for n in names} for a in axes}, 0, smooth, False)
    prof = profile(problem, sol, mask, start, names, _reach(names))
    restarts = 0
    better = {a: [p.better for p in prof[a].values() if p.better is not None] for a in axes}
    if any(better.values()):   # the optimum was not one: fit again from the lowest point
        moved = dict(sol.params)
        for a in axes:
            if better[a]:
                moved[a] = min(better[a], key=lambda b: b[0])[1]
        sol = solve(problem, moved, coords, mask, start, max_nfev=max_nfev)
        prof = profile(problem, sol, mask, start, names, _reach(names))
        restarts = 1
    intervals = {a: {n: (prof[a][n].low, prof[a][n].high) for n in names} for a in axes}
    linear = {a: {n: prof[a][n].half for n in names} for a in axes}
    optimum = sol   # its Jacobian has every coordinate's column (none held yet)
    loose = {a: [n for n in ANCHORS if n in names and _wide(
        n, prof[a][n], coordinate(sol.params[a], start[a], n))] for a in axes}
    held: dict[str, dict[str, str]] = {a: {} for a in axes}
    kept: dict[str, dict[str, float]] = {a: {} for a in axes}
    given: dict[str, dict[str, tuple[str, ...]]] = {a: {} for a in axes}
    current = dict(sol.params)
    for last in [False] * ROUNDS + [True]:
        if not any(loose.values()):
            break
        for a in axes:   # the first of each axis' group; after the rounds, all that is left
            for n in (loose[a] if last else loose[a][:1]):
                kept[a][n], held[a][n] = _hold(start[a], n, intervals[a][n])
                current[a] = _set(current[a], start[a], n, kept[a][n])
            loose[a] = [] if last else loose[a][1:]
        frozen = {a: {own_coordinate(n) for n in held[a]} for a in axes}
        sol = solve(problem, current, coords, mask, start, max_nfev=max_nfev + 1,
                    frozen=frozen)
        current = dict(sol.params)
        rest = sorted({n for a in axes for n in loose[a]})
        if not rest:
            break
        # only whether each closes within its tolerance matters here: a side still below
        # the threshold there ends the profile (the interval reported is the first one)
        again = profile(problem, sol, mask, start, rest, _reach(rest),
                        settle={n: TOLERANCE[n] for n in rest})
        for a in axes:
            for n in list(loose[a]):
                p = again[a].get(n)
                if p is not None and not _wide(n, p, coordinate(sol.params[a], start[a], n)):
                    given[a][n] = tuple(held[a])
                    intervals[a][n] = (p.low, p.high)
                    loose[a].remove(n)
    for a in axes:   # a held quantity whose own coordinate is relative: exactly its value
        for n, x in kept[a].items():
            current[a] = _set(current[a], start[a], n, x)
        # a value the holds moved out of its interval, or by more than half its
        # half-interval, depends on what was held, and so does one that a held value,
        # anywhere within its own reach, would move by more than its half-interval (the
        # optimum's Jacobian: the others re-fitted)
        lean = _leaning(optimum, a, names, list(held[a]))
        for n in names:
            if n in held[a] or n in given[a] or not held[a]:
                continue
            lo, hi = intervals[a][n]
            x = coordinate(current[a], start[a], n)
            half = 0.5 * (hi - lo) if math.isfinite(hi - lo) else math.inf
            moved = abs(x - coordinate(optimum.params[a], start[a], n))
            if not lo - 1e-12 <= x <= hi + 1e-12 or max(2.0 * moved, lean.get(n, 0.0)) > half:
                given[a][n] = tuple(held[a])
    return Joint(current, intervals, held, given, linear, restarts, smooth)


def _leaning(sol: Solution, axis: str, names: Sequence[str], held: Sequence[str]
             ) -> dict[str, float]:
    """Per quantity of ``names`` not held: how far (in its coordinate) it moves when the
    ``held`` ones move over their profile's reach (2·``TOLERANCE``) and every other
    coordinate is re-fitted, to first order at ``sol`` (each held one on its own; the
    largest)."""
    jac, free = sol.jac[axis], sol.free[axis]
    cols = [sol.names.index(own_coordinate(h)) for h in held]
    rest = [i for i in np.flatnonzero(free) if i not in cols]
    out: dict[str, float] = {}
    if not rest:
        return out
    pinv = np.linalg.pinv(jac[:, rest], rcond=1e-7)
    for h, c in zip(held, cols, strict=True):
        step = np.zeros(len(sol.names))
        step[c] = 2.0 * TOLERANCE[h]
        step[rest] = -pinv @ (jac[:, c] * step[c])
        for n in names:
            if n in held:
                continue
            w = QUANTITY.get(n, {n: 1.0})
            moved = abs(sum(k * step[sol.names.index(m)] for m, k in w.items()
                            if m in sol.names))
            out[n] = max(out.get(n, 0.0), moved)
    return out


def _hold(base: AxisParams, name: str, interval: tuple[float, float]) -> tuple[float, str]:
    """The value (coordinate) a quantity the data do not pin down is held at: BASE's, or
    the end of its interval nearest to it where the data reject BASE's; and which."""
    lo, hi = interval
    keep, how = coordinate(base, base, name), "base"
    if math.isfinite(lo) and keep < lo:
        keep, how = lo, "bound"
    elif math.isfinite(hi) and keep > hi:
        keep, how = hi, "bound"
    return keep, how


def _set(p: AxisParams, base: AxisParams, name: str, x: float) -> AxisParams:
    """``p`` with quantity ``name`` at ``x`` (the inertia with the friction and gain in
    proportion: what the data fix are their ratios)."""
    own = "scale" if name == "inertia" else name
    lo, hi = BOUNDS[own]
    return with_coordinate(p, base, own, min(max(x, lo), hi))
