"""Confidence intervals from the data actually recorded: the profile likelihood.

For each fitted coordinate θ_i the fit's cost is profiled: θ_i is moved off the optimum and
every other free coordinate re-fitted, and the 95 % interval is where the rise of the
re-fitted cost stays below the F threshold (``threshold``). Each point of the profile is a
real replay of the twin (the nuisance coordinates re-fitted by two Gauss-Newton steps with
the optimum's Jacobian, each checked by a replay), so a cost that is flat along a
parameter — two parameters that trade off, a parameter the experiments do not excite — shows
as an interval with no end, whatever the Jacobian at the optimum claims; and a profile point
with a lower cost than the optimum shows that the optimum was not one.

The replay's residuals are correlated in time (the replay floor is smooth), so ``n``
samples carry about ``n/τ`` independent errors, τ the residuals' integrated autocorrelation
time: the threshold is scaled by τ (``effective_samples``). As in ``lsq``, one replay moves
the same coordinate of every axis, each by its own amount.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import f as f_dist

from twin.identify.lsq import BOUNDS, COORDS, Solution, coordinate, with_coordinates
from twin.identify.parallel import split_map
from twin.identify.replay import AxisParams, Problem

__all__ = ["FLOOR", "QUANTITY", "Profile", "autocorrelation_time", "noise_variance",
           "own_coordinate", "profile", "profile_of", "systematic_variance", "threshold"]

LEVEL = 0.95
"""Confidence level of the intervals."""


def autocorrelation_time(res: np.ndarray, channels: int = 2) -> float:
    """The residuals' integrated autocorrelation time (samples, ≥ 1): 1 + 2·Σ ρ(lag) up to
    the first lag where ρ falls below 0.05, the largest over the ``channels`` series
    (position, then tacho) ``res`` is the concatenation of."""
    tau = 1.0
    for part in np.split(res, channels):
        x = part - part.mean()
        var = float(x @ x)
        if var <= 0.0 or len(x) < 4:
            continue
        t = 1.0
        # FFT autocorrelation: all lags at once
        n = len(x)
        spec = np.fft.rfft(x, 2 * n)
        acf = np.fft.irfft(spec * np.conj(spec))[:n] / var
        for lag in range(1, n // 4):
            if acf[lag] <= 0.05:
                break
            t += 2.0 * acf[lag]
        tau = max(tau, t)
    return tau


FLOOR = 1.0
"""Least residual variance (in the residuals' scaled units: ``replay.SIGMA_POSITION``,
``replay.SIGMA_TACHO``, the replay's own floor). A replay that agrees with the machine
better than its own floor (the mains phase known to a fraction of a degree, the state the
experiments started from) says nothing more about the parameters: a noiseless machine would
otherwise get intervals of 0.1 % around a value its floor biases by 0.5 %."""


def noise_variance(res: np.ndarray, parameters: int) -> float:
    """The residuals' variance per sample, s² = SSE/(n − p), but not below ``FLOOR``."""
    return max(float(res @ res) / max(len(res) - parameters, 1), FLOOR)


def systematic_variance(res: np.ndarray, channels: int = 2) -> float:
    """The part of the residuals' variance per sample that is not white noise (in their
    scaled units): per channel of the ``channels`` series ``res`` is the concatenation of,
    mean(r²) − mean(Δr²)/2 (for white noise of variance σ² both terms are σ²; a smooth
    misfit adds its variance to the first and almost nothing to the second), not below 0;
    the mean over the channels."""
    out = 0.0
    for part in np.split(res, channels):
        if len(part) < 2:
            continue
        d = np.diff(part)
        out += max(float(part @ part) / len(part) - 0.5 * float(d @ d) / len(d), 0.0)
    return out / channels


def threshold(res: np.ndarray, parameters: int, level: float = LEVEL) -> float:
    """The rise of the cost (sum of squared residuals) that bounds the ``level`` profile
    interval of one parameter: F(1, n_eff − p)·s²·τ, with s² = ``noise_variance``, τ the
    autocorrelation time and n_eff = n/τ the effective number of samples."""
    n = len(res)
    tau = autocorrelation_time(res)
    n_eff = max(n / tau, parameters + 2.0)
    return float(f_dist.ppf(level, 1, n_eff - parameters)) * noise_variance(
        res, parameters) * tau


IMPROVE = 0.25
"""A profile point counts as better than the optimum (``Profile.better``: the fit is run
again from it) when its cost is below the optimum's by this share of the threshold. A
smaller dip only widens the interval, never narrows it (its ends are placed against the
optimum's cost, above the least one), by about an eighth of its half-width at most: not
worth a second fit and profile."""


@dataclass
class Profile:
    """The profile interval of one coordinate of one axis (in the coordinate).

    Attributes
    ----------
    low, high : float
        Interval ends (NaN: the cost did not rise enough before ``reach``: open).
    half : float
        The linearised half-interval at the optimum (what the Jacobian alone says).
    better : (float, AxisParams) or None
        The lowest point of the profile whose cost is below the optimum's, if one was met:
        (the cost's change, the parameters there).
    """

    low: float
    high: float
    half: float
    better: tuple[float, AxisParams] | None = None

    @property
    def open(self) -> bool:
        """The interval has no end on some side within the search."""
        return not (math.isfinite(self.low) and math.isfinite(self.high))


QUANTITY = {"inertia": {"scale": 1.0},
            "coulomb": {"scale": 1.0, "coulomb_rel": 1.0},
            "viscous": {"scale": 1.0, "viscous_rel": 1.0},
            "speed_kp": {"scale": 1.0, "speed_kp_rel": 1.0}}
"""Reported quantities in the fitted coordinates (their ``lsq.coordinate`` is the weighted
sum); any other name is its own coordinate."""


def own_coordinate(name: str) -> str:
    """The fitted coordinate that carries quantity ``name`` (the one held to hold it)."""
    return {"inertia": "scale"}.get(name, f"{name}_rel" if name in QUANTITY else name)


def profile(problem: Problem, sol: Solution, mask: np.ndarray, start: dict[str, AxisParams],
            names: Sequence[str], reach: dict[str, float],
            settle: dict[str, float] | None = None) -> dict[str, dict[str, Profile]]:
    """``profile_of`` each quantity of ``names``, the quantities split over the processes
    ``parallel.split_map`` may use (each quantity's profile is independent of the
    others': the same intervals as one after the other)."""
    names = list(names)
    groups = [names[0::2], names[1::2]] if len(names) > 1 else [names]
    parts = split_map(problem, lambda g: profile_of(problem, sol, mask, start, g, reach,
                                                     settle),
                      groups)
    out: dict[str, dict[str, Profile]] = {a: {} for a in problem.axes}
    for part in parts:
        for a, v in part.items():
            out.setdefault(a, {}).update(v)
    return {a: {n: out[a][n] for n in names if n in out[a]} for a in out}


def profile_of(problem: Problem, sol: Solution, mask: np.ndarray,
               start: dict[str, AxisParams], names: Sequence[str], reach: dict[str, float],
               settle: dict[str, float] | None = None) -> dict[str, dict[str, Profile]]:
    """The profile intervals of the quantities ``names`` (``QUANTITY``; in
    ``lsq.coordinate`` units) of every axis whose own coordinate is free in ``sol``.

    Parameters
    ----------
    problem, sol, mask, start
        The problem, its solution (with each axis' Jacobian and residuals), the ticks the
        cost is taken over and BASE's parameters.
    names : sequence of str
        The quantities to profile.
    reach : dict of str to float
        How far from the optimum (in the quantity's coordinate) the profile is searched:
        an interval wider than that is reported open.
    settle : dict of str to float, optional
        Where only whether the interval closes within a half-width matters (``joint``:
        a quantity profiled again after another was held is identified given it only if
        its interval closes within ``TOLERANCE``): a side whose point at that distance or
        beyond is still below the threshold ends the quantity's profile there, open on that
        side (the cost does not rise by the threshold within the half-width: the points a
        full profile would add cannot close it).

    Each side takes one point where the linearised profile crosses the threshold; the end
    is placed where that point's rise says (the square root of the rise is linear in the
    distance for a quadratic cost), and checked by a second point where the first rose to
    less than half or more than twice the threshold; where that second point fell below
    the threshold inside a first that rose above it, a third halves the bracket and the
    end is the nearest point above (``_ends``); each point costs two replays (a point is a real
    replay with the others re-fitted about, so its rise is at least the profile's: a rise
    below the threshold is certain). A side whose room to the coordinate's bound is
    below a thousandth of its finite-difference step ends at the bound, without a point.
    The first points of both sides come before the second ones.
    """
    axes = list(problem.axes)
    crit = {a: threshold(sol.res[a], int(sol.free[a].sum())) for a in axes}
    sse0 = {a: sol.sse(a) for a in axes}
    out: dict[str, dict[str, Profile]] = {a: {} for a in axes}
    for name in names:
        piv = sol.names.index(own_coordinate(name))
        todo = [a for a in axes if sol.free[a][piv]]
        if not todo:
            continue
        w = np.array([QUANTITY.get(name, {name: 1.0}).get(n, 0.0) for n in sol.names])
        dirs, fixed, half = {}, {}, {}
        for a in todo:
            others = np.flatnonzero(sol.free[a] & (np.arange(len(w)) != piv))
            move = np.zeros((len(w), len(others)))   # nuisance moves keeping the quantity
            for c, j in enumerate(others):
                move[j, c] = 1.0
                move[piv, c] = -w[j] / w[piv]
            along = np.zeros(len(w))
            along[piv] = 1.0 / w[piv]
            d = sol.jac[a] @ move
            # a relative cut-off: columns that trade off exactly must not blow the step up
            dirs[a] = (move, np.linalg.pinv(d, rcond=1e-7) if d.size
                       else np.zeros((0, len(sol.res[a]))))
            fixed[a] = along
            g = sol.jac[a] @ along
            resid = g - d @ (dirs[a][1] @ g) if d.size else g
            curv = float(resid @ resid)
            half[a] = math.sqrt(crit[a] / curv) if curv > 0.0 else math.inf
        x0 = {a: coordinate(sol.params[a], start[a], name) for a in todo}
        lo_b, hi_b = BOUNDS[own_coordinate(name)] if name not in QUANTITY else (-math.inf,
                                                                                 math.inf)
        ends = {a: [math.nan, math.nan] for a in todo}
        better: dict[str, tuple[float, AxisParams] | None] = {a: None for a in todo}
        tiny = 1e-3 * COORDS[own_coordinate(name)][1]
        limit, delta = [], []
        for side, sign in enumerate((-1.0, 1.0)):
            room = {a: max(0.0, min(reach[name], (hi_b - x0[a]) if sign > 0
                                    else (x0[a] - lo_b))) for a in todo}
            for a in todo:
                if room[a] <= tiny:   # at the bound: the interval ends there
                    ends[a][side] = x0[a]
            limit.append(room)
            delta.append({a: min(half[a], room[a]) for a in todo if room[a] > tiny})
        seen: list[dict[str, list[tuple[float, float]]]] = [{}, {}]
        settled: set[str] = set()
        for attempt in range(POINTS):   # the first point of both sides, then the next ones
            for side, sign in enumerate((-1.0, 1.0)):
                todo_side = {a: d for a, d in delta[side].items() if a not in settled}
                if not todo_side:
                    delta[side] = {}
                    continue
                rise, moved = _point(problem, sol, mask, start, fixed, dirs,
                                     {a: sign * d for a, d in todo_side.items()}, sse0)
                delta[side] = _ends(todo_side, rise, moved, crit, limit[side], seen[side],
                                    ends, x0, side, sign, attempt, better)
                if settle is not None:   # below the threshold beyond the tolerance:
                    for a, d in todo_side.items():   # wide, whatever the other points say
                        if rise[a] < crit[a] and d >= settle[name] * (1.0 - 1e-9):
                            ends[a][side] = math.nan
                            settled.add(a)
        for a in todo:
            out[a][name] = Profile(ends[a][0], ends[a][1], half[a], better[a])
    return out


POINTS = 3
"""Profile points per side at most: the first, the one that checks it, and one more only
where the second fell below the threshold inside a first that rose above it (the end lies
between them: the third halves that bracket)."""


def _ends(delta: dict[str, float], rise: dict[str, float], moved: dict[str, AxisParams],
          crit: dict[str, float], limit: dict[str, float],
          seen: dict[str, list[tuple[float, float]]], ends: dict[str, list[float]],
          x0: dict[str, float], side: int, sign: float, attempt: int,
          better: dict[str, tuple[float, AxisParams] | None]) -> dict[str, float]:
    """One profile point's verdict per axis (``profile_of``): the end it places on its
    side, a lower point than the optimum (``better``), and where the next point of the side
    goes (returned; none where this one settles the end).

    ``seen[axis]`` collects the side's points, in order, as (distance, √rise). The end lies
    beyond the furthest point below the threshold (certain: the others only re-fitted
    about, a point's rise is at least the profile's). Where a point further out rose above
    it, the end is placed on the secant of √rise between the two (exact for a quadratic
    cost; the optimum counts as a point below). Where the point below was taken inside one
    that had risen above (a profile flat, then steep: a dead zone), √rise is not linear
    between them and their secant would end the interval inside the flat part, narrower
    than the data allow: the end is then the nearest point above, after one more point
    halfway between them. With no point above, the end is extrapolated from the furthest
    point below."""
    nxt = {}
    for a, d in delta.items():
        r = rise[a]
        if r < -IMPROVE * crit[a] and (better[a] is None or r < better[a][0]):
            better[a] = (r, moved[a])
        q, qr = math.sqrt(crit[a]), math.sqrt(max(r, 0.0))
        points = seen.setdefault(a, [(0.0, 0.0)])   # the optimum: no rise
        points.append((d, qr))
        k_below = max((k for k, p in enumerate(points) if p[1] < q),
                      key=lambda k: points[k][0])
        below = points[k_below]
        above = [p for p in points if p[1] >= q and p[0] > below[0]]
        inside = any(p in above for p in points[:k_below])   # below taken after above
        if above and not inside:   # the end lies between: secant on sqrt(rise)
            out = min(above, key=lambda p: p[0])
            est = below[0] + (out[0] - below[0]) * (q - below[1]) / (out[1] - below[1])
            ends[a][side] = x0[a] + sign * est
            if attempt == 0 and r > 2.0 * crit[a]:
                nxt[a] = est   # a far first point's end checked by a second
        elif above:   # a point below inside one above: the nearest above, after a halving
            out = min(above, key=lambda p: p[0])
            ends[a][side] = x0[a] + sign * out[0]
            if attempt == 1:
                nxt[a] = 0.5 * (below[0] + out[0])
        elif d >= limit[a] * (1.0 - 1e-9):
            ends[a][side] = math.nan   # open within the reach
        else:   # below the threshold: on, as far as the square root says
            est = d * q / qr if qr > 0.0 else limit[a]
            close = r > 0.5 * crit[a] or attempt >= 1
            ends[a][side] = (x0[a] + sign * est if close and est < limit[a]
                             else math.nan)
            if attempt == 0 and r <= 0.5 * crit[a]:
                nxt[a] = min(est * 1.05, limit[a])
    return nxt


def _point(problem: Problem, sol: Solution, mask: np.ndarray, start: dict[str, AxisParams],
           fixed: dict[str, np.ndarray], dirs: dict[str, tuple[np.ndarray, np.ndarray]],
           delta: dict[str, float], sse0: dict[str, float]
           ) -> tuple[dict[str, float], dict[str, AxisParams]]:
    """The cost's rise with the quantity moved by ``delta[axis]`` and the nuisance
    re-fitted (two Gauss-Newton steps on the optimum's Jacobian, each replayed; the lower
    cost is kept). Returns the rise and the parameters there, per axis."""
    x0 = {a: np.array([coordinate(sol.params[a], start[a], n) for n in sol.names])
          for a in delta}
    first, t = dict(sol.params), {}
    for a, d in delta.items():
        move, pinv = dirs[a]
        z = -pinv @ (sol.res[a] + sol.jac[a] @ (fixed[a] * d))
        t[a] = fixed[a] * d + move @ z
        first[a] = _at(sol, start, a, x0[a] + t[a])
    r1 = problem.residuals(first, mask)
    second = dict(first)
    for a in delta:
        move, pinv = dirs[a]
        second[a] = _at(sol, start, a, x0[a] + t[a] + move @ (-pinv @ r1[a]))
    r2 = problem.residuals(second, mask)
    rise, moved = {}, {}
    for a in delta:
        s1, s2 = float(r1[a] @ r1[a]), float(r2[a] @ r2[a])
        rise[a], moved[a] = (s1 - sse0[a], first[a]) if s1 <= s2 else (s2 - sse0[a],
                                                                         second[a])
    return rise, moved


def _at(sol: Solution, start: dict[str, AxisParams], a: str, x: np.ndarray) -> AxisParams:
    on = sol.free[a]
    names = [n for n, f in zip(sol.names, on, strict=True) if f]
    return with_coordinates(sol.params[a], start[a], names, x[on])
