"""The least-squares machinery of the fit: the fitted coordinates, ``scipy.optimize.
least_squares`` on replays of both axes at once, and the scan for the mains phase.

Coordinates are the log of a parameter's ratio to BASE (inertia, friction multipliers,
armature R and L, the regulators' settings), or linear (break-away ratio − 1, lost motion).
The axes are uncoupled, so one replay moves both: the Jacobian callable perturbs coordinate
``c`` of every axis at once, and one simulation gives the column of ``c`` of x and the same
column of y (the Jacobian is block-diagonal by axis). The library's trust-region reflective
method (``trf``) then steps both axes in one problem, inside the coordinates' bounds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from twin.config import AXES
from twin.identify.parallel import split_map
from twin.identify.replay import AxisParams, Problem

__all__ = ["BOUNDS", "COORDS", "Solution", "coordinate", "scan_mains_phase", "solve",
           "with_coordinate", "with_coordinates"]

COORDS = {"scale": ("log", 0.01), "inertia": ("log", 0.01), "coulomb": ("log", 0.02),
          "viscous": ("log", 0.05), "breakaway": ("lin", 0.2), "backlash": ("lin", 2e-6),
          "resistance": ("log", 0.03), "inductance": ("log", 0.03),
          "coulomb_rel": ("log", 0.02), "viscous_rel": ("log", 0.05),
          "speed_kp": ("log", 0.02), "speed_kp_rel": ("log", 0.02),
          "speed_ti": ("log", 0.03), "reference_filter": ("log", 0.03),
          "current_kp": ("log", 0.05), "current_ti": ("log", 0.05),
          "brush_drop": ("lin", 0.1)}
"""The fitted coordinates: name → (transform: log of the ratio to BASE, or linear;
finite-difference step). ``scale`` moves the inertia with the friction and the speed
regulator's gain in proportion (the coast-downs fix friction over inertia, the speed steps
the gain over inertia); ``<name>_rel`` is ``<name>`` over that proportion (the log of its
ratio to BASE less ``scale``), so that the least squares steps along the valley, not across
it."""

_RATIO = ("coulomb", "viscous")
"""Coordinates that are already multipliers of BASE (their log is the coordinate)."""

_SCALED = ("inertia", "coulomb", "viscous", "speed_kp")
"""What ``scale`` moves together (the speed regulator's gain where the parameters carry
it)."""

BOUNDS = {n: (math.log(0.2), math.log(5.0)) for n, (kind, _h) in COORDS.items()
          if kind == "log"}
BOUNDS.update({"coulomb": (math.log(0.05), math.log(20.0)),
               "viscous": (math.log(0.01), math.log(100.0)),
               "coulomb_rel": (math.log(0.05), math.log(20.0)),
               "viscous_rel": (math.log(0.01), math.log(100.0)),
               "resistance": (math.log(0.3), math.log(3.0)),
               "inductance": (math.log(0.3), math.log(3.0)),
               "breakaway": (0.0, 4.0), "backlash": (0.0, 200e-6), "brush_drop": (0.0, 4.0)})
"""Bounds of each coordinate (log of the ratio to BASE, or the linear value)."""


def _log_ratio(p: AxisParams, base: AxisParams, name: str) -> float:
    v = getattr(p, name)
    return math.log(v) if name in _RATIO else math.log(v / getattr(base, name))


def coordinate(p: AxisParams, base: AxisParams, name: str) -> float:
    """The value of coordinate ``name`` of ``p``, BASE being ``base``."""
    if name == "scale":   # inertia with the friction scaled along (their ratios held)
        return math.log(p.inertia / base.inertia)
    if name.endswith("_rel"):
        return _log_ratio(p, base, name[:-4]) - math.log(p.inertia / base.inertia)
    if COORDS[name][0] == "log":
        return _log_ratio(p, base, name)
    return getattr(p, name) - 1.0 if name == "breakaway" else getattr(p, name)


def with_coordinate(p: AxisParams, base: AxisParams, name: str, x: float) -> AxisParams:
    """``p`` with coordinate ``name`` set to ``x`` (``coordinate``'s inverse; the
    break-away and the lost motion are kept ≥ their least value)."""
    if name == "scale":
        f = base.inertia * math.exp(x) / p.inertia
        return p.with_(**{n: getattr(p, n) * f for n in _SCALED if hasattr(p, n)})
    if name.endswith("_rel"):
        own = name[:-4]
        ref = 1.0 if own in _RATIO else getattr(base, own)
        return p.with_(**{own: ref * math.exp(x) * p.inertia / base.inertia})
    if COORDS[name][0] == "log":
        ref = 1.0 if name in _RATIO else getattr(base, name)
        return p.with_(**{name: ref * math.exp(x)})
    if name == "breakaway":
        return p.with_(breakaway=1.0 + max(x, 0.0))
    return p.with_(**{name: max(x, 0.0)})


def with_coordinates(p: AxisParams, base: AxisParams, names: Sequence[str],
                     x: Sequence[float]) -> AxisParams:
    """``p`` with the coordinates ``names`` set to ``x`` (each clipped to its bounds;
    ``scale`` first, so that the relative ones keep their meaning)."""
    pairs = sorted(zip(names, x, strict=True), key=lambda nx: nx[0] != "scale")
    for n, v in pairs:
        p = with_coordinate(p, base, n, min(max(float(v), BOUNDS[n][0]), BOUNDS[n][1]))
    return p


@dataclass
class Solution:
    """A solved least-squares problem.

    Attributes
    ----------
    params : dict of str to AxisParams
        The parameters at the solution.
    names : list of str
        The coordinates it solved for.
    jac : dict of str to ndarray
        Per axis: the Jacobian (residuals × ``names``) at the solution; the columns of a
        coordinate held for that axis are zero.
    res : dict of str to ndarray
        Per axis: the residual vector at the solution.
    free : dict of str to ndarray
        Per axis: which of ``names`` were free (bool).
    """

    params: dict[str, AxisParams]
    names: list[str]
    jac: dict[str, np.ndarray]
    res: dict[str, np.ndarray]
    free: dict[str, np.ndarray]

    def sse(self, axis: str) -> float:
        """Sum of squared (scaled) residuals of ``axis``."""
        return float(self.res[axis] @ self.res[axis])


class _Packed:
    """The free coordinates of every axis as one vector, and back."""

    def __init__(self, problem: Problem, params: dict[str, AxisParams], names: Sequence[str],
                 start: dict[str, AxisParams], frozen: dict[str, set[str]]):
        self.problem, self.start, self.names = problem, start, list(names)
        self.base_params = dict(params)
        self.slots = [(a, n) for a in problem.axes for n in self.names
                      if n not in frozen.get(a, ())]

    def vector(self, params: dict[str, AxisParams]) -> np.ndarray:
        return np.array([coordinate(params[a], self.start[a], n) for a, n in self.slots])

    def params(self, x: np.ndarray) -> dict[str, AxisParams]:
        out = dict(self.base_params)
        for a in self.problem.axes:
            mine = [(n, v) for (b, n), v in zip(self.slots, x, strict=True) if b == a]
            if mine:
                names, values = zip(*mine, strict=True)
                out[a] = with_coordinates(out[a], self.start[a], names, values)
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.array([BOUNDS[n][0] for _, n in self.slots])
        hi = np.array([BOUNDS[n][1] for _, n in self.slots])
        return lo, hi


def solve(problem: Problem, params: dict[str, AxisParams], names: Sequence[str],
          mask: np.ndarray, start: dict[str, AxisParams], *, max_nfev: int = 8,
          frozen: dict[str, set[str]] | None = None) -> Solution:
    """Least squares (``scipy.optimize.least_squares``, trust-region reflective, bounded)
    on the coordinates ``names`` of the problem's axes at once, but those ``frozen[axis]``
    holds for that axis. ``max_nfev`` bounds the residual evaluations (each Jacobian costs
    one replay per coordinate on top). Returns the solution with each axis' Jacobian and
    residuals at it.

    Every Jacobian is replayed, even one a hundredth of a finite-difference step from the
    last: the replay's cost is rough on that scale, and on an unseen machine
    (seed 21, axis x, amplitude 1) the profile intervals taken with the last Jacobian
    instead closed around a resistance 27 % off, which those with a fresh one left open."""
    frozen = frozen or {}
    pack = _Packed(problem, params, names, start, frozen)
    axes = problem.axes
    cache: dict[bytes, dict[str, np.ndarray]] = {}

    def residuals(x: np.ndarray) -> dict[str, np.ndarray]:
        key = np.asarray(x, float).tobytes()
        if key not in cache:
            if len(cache) > 64:
                cache.clear()
            cache[key] = problem.residuals(pack.params(x), mask)
        return cache[key]

    def fun(x: np.ndarray) -> np.ndarray:
        r = residuals(x)
        return np.concatenate([r[a] for a in axes])

    sizes = None

    def jac(x: np.ndarray) -> np.ndarray:
        nonlocal sizes
        r0 = residuals(x)
        sizes = [len(r0[a]) for a in axes]
        rows = np.cumsum([0, *sizes])
        out = np.zeros((rows[-1], len(x)))
        lo, hi = pack.bounds()
        trials = []
        for name in pack.names:   # one replay per coordinate, every axis' column at once
            cols = [i for i, (_a, n) in enumerate(pack.slots) if n == name]
            if not cols:
                continue
            h = COORDS[name][1]
            trial = np.array(x, float)
            step = np.where(x[cols] + h <= hi[cols], h, -h)
            step = np.where(x[cols] + step >= lo[cols], step, h)
            trial[cols] = x[cols] + step
            trials.append((cols, step, trial))
        # the columns are independent replays: side by side where two processes may run
        done = split_map(problem, lambda t: residuals(t[2]), trials)
        for (cols, step, _trial), r1 in zip(trials, done, strict=True):
            for c, s in zip(cols, step, strict=True):
                a = pack.slots[c][0]
                k = axes.index(a)
                out[rows[k]:rows[k + 1], c] = (r1[a] - r0[a]) / s
        return out

    x0 = np.clip(pack.vector(params), *pack.bounds())
    if len(x0):
        scale = np.array([max(COORDS[n][1] * 10.0, 1e-12) for _, n in pack.slots])
        sol = least_squares(fun, x0, jac=jac, bounds=pack.bounds(), method="trf",
                            x_scale=scale, max_nfev=max_nfev, ftol=1e-4, xtol=1e-4,
                            gtol=1e-8)
        x = sol.x
        full = sol.jac
    else:
        x = x0
        full = np.zeros((len(fun(x0)), 0))
    out_params = pack.params(x)
    res = residuals(x)
    if full.shape[0] != sum(len(res[a]) for a in axes):
        full = jac(x)
    rows = np.cumsum([0, *[len(res[a]) for a in axes]])
    jacs, free = {}, {}
    for k, a in enumerate(axes):
        j = np.zeros((len(res[a]), len(pack.names)))
        on = np.zeros(len(pack.names), dtype=bool)
        for c, (b, n) in enumerate(pack.slots):
            if b == a:
                i = pack.names.index(n)
                j[:, i] = full[rows[k]:rows[k + 1], c]
                on[i] = True
        jacs[a], free[a] = j, on
    return Solution(out_params, pack.names, jacs, res, free)


def scan_mains_phase(problem: Problem, params: dict[str, AxisParams], steps: int = 36, *,
                     near: int | None = None, golden: int = 5) -> None:
    """The mains phase that best replays the speed steps: a scan of one pulse period, then
    a golden-section search around the best point of the grid. A drive without the
    adaptation to discontinuous conduction replays well only within a few degrees of the
    right phase (its current pulses at feed speeds decide how each step starts), hence the
    fine grid over all the steps. ``near``: only the ``near`` grid points either side of
    the problem's present phase (a scan again after the parameters moved a little);
    ``golden``: the golden-section iterations after the grid (0: the grid's best)."""
    base = problem.base
    if not any(base.axes[a].converter.kind == "thyristor" for a in AXES):
        return
    p = base.axes["x"].converter.pulse_number
    first = problem.log.experiment_mask("steps")

    def sse(phase: float) -> float:
        problem.mains_phase = phase % (2.0 * math.pi)
        r = problem.residuals(params, first)
        return sum(float(v @ v) for v in r.values())

    period = 2.0 * math.pi / p
    step = period / steps
    if near is None or problem.mains_phase is None:   # k/steps: one grid's points are
        grid = [k / steps * period for k in range(steps)]   # bit for bit a finer one's
    else:
        grid = [problem.mains_phase + k * step for k in range(-near, near + 1)]
    values = split_map(problem, sse, grid)   # independent replays, side by side
    best = grid[int(np.argmin(values))]
    if golden <= 0:
        problem.mains_phase = best % (2.0 * math.pi)
        return
    lo, hi = best - step, best + step
    ratio = 0.5 * (math.sqrt(5.0) - 1.0)
    c, d = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    fc, fd = sse(c), sse(d)
    for _ in range(golden):
        if fc < fd:
            hi, d, fd = d, c, fc
            c = hi - ratio * (hi - lo)
            fc = sse(c)
        else:
            lo, c, fc = c, d, fd
            d = lo + ratio * (hi - lo)
            fd = sse(d)
    candidates = [(min(values), best), (fc, c), (fd, d)]
    problem.mains_phase = min(candidates)[1] % (2.0 * math.pi)
