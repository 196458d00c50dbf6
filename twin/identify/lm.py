"""The least-squares machinery of the fit: the fitted coordinates, Levenberg-Marquardt on
replays of both axes at once, confidence intervals, and the scan for the mains phase.

Coordinates are the log of a parameter's ratio to BASE (inertia, friction multipliers,
armature R and L), or linear (break-away ratio − 1, lost motion). The axes are uncoupled, so
one replay moves both: a finite-difference column of x and the same column of y come from
one simulation, and each axis gets its own damped Gauss-Newton step.
"""

from __future__ import annotations

import math

import numpy as np

from twin.config import AXES
from twin.identify.replay import AxisParams, Problem

__all__ = ["BOUNDS", "COORDS", "coordinate", "half_intervals", "levenberg_marquardt",
           "scan_mains_phase", "with_coordinate"]

COORDS = (("scale", "log", 0.01), ("inertia", "log", 0.01), ("coulomb", "log", 0.02),
           ("viscous", "log", 0.05), ("breakaway", "lin", 0.2), ("backlash", "lin", 2e-6),
           ("resistance", "log", 0.03), ("inductance", "log", 0.03))
"""The fitted coordinates: name, transform (log of the ratio to BASE, or linear) and
finite-difference step. ``scale`` moves the inertia with the friction in proportion (the
coast-downs fix friction over inertia)."""


def coordinate(p: AxisParams, base: AxisParams, name: str, kind: str) -> float:
    """The value of coordinate ``name`` (of transform ``kind``) of ``p``, BASE being
    ``base``."""
    if name == "scale":  # inertia with the friction scaled along (their ratios held)
        return math.log(p.inertia / base.inertia)
    v = getattr(p, name)
    if kind == "log":
        ref = getattr(base, name)
        return math.log(v / ref) if name in ("inertia", "resistance", "inductance") \
            else math.log(v)
    return v - 1.0 if name == "breakaway" else v


def with_coordinate(p: AxisParams, base: AxisParams, name: str, kind: str, x: float
                    ) -> AxisParams:
    """``p`` with coordinate ``name`` set to ``x`` (``coordinate``'s inverse; the
    break-away and the lost motion are kept ≥ their least value)."""
    if name == "scale":
        f = base.inertia * math.exp(x) / p.inertia
        return p.with_(inertia=p.inertia * f, coulomb=p.coulomb * f, viscous=p.viscous * f)
    if kind == "log":
        ref = getattr(base, name) if name in ("inertia", "resistance", "inductance") else 1.0
        return p.with_(**{name: ref * math.exp(x)})
    if name == "breakaway":
        return p.with_(breakaway=1.0 + max(x, 0.0))
    return p.with_(**{name: max(x, 0.0)})


BOUNDS = {"scale": (math.log(0.2), math.log(5.0)), "inertia": (math.log(0.2), math.log(5.0)),
           "coulomb": (math.log(0.05), math.log(20.0)),
           "viscous": (math.log(0.01), math.log(100.0)),
           "breakaway": (0.0, 4.0), "backlash": (0.0, 200e-6),
           "resistance": (math.log(0.3), math.log(3.0)),
           "inductance": (math.log(0.3), math.log(3.0))}


def levenberg_marquardt(problem: Problem, params: dict[str, AxisParams], names: list[str],
        mask: np.ndarray, start: dict[str, AxisParams], *, iterations: int = 8,
        frozen: dict[str, set[str]] | None = None
        ) -> tuple[dict[str, AxisParams], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Levenberg-Marquardt on the coordinates ``names`` of the problem's axes at once (but
    those ``frozen[axis]`` holds for that axis); returns the parameters, each axis' Jacobian
    (residuals × coordinates) at the solution and its residual vector."""
    coords = [c for c in COORDS if c[0] in names]
    frozen = frozen or {}
    axes = problem.axes
    active = {a: np.array([c[0] not in frozen.get(a, ()) for c in coords]) for a in axes}
    lam = {a: 1e-2 for a in axes}
    res = problem.residuals(params, mask)
    sse = {a: float(res[a] @ res[a]) for a in axes}
    jac: dict[str, np.ndarray] = {}
    for _ in range(iterations):
        jac = {a: np.empty((len(res[a]), len(coords))) for a in axes}
        for i, (name, kind, h) in enumerate(coords):
            trial, steps = dict(params), {}
            for a in axes:
                x = coordinate(params[a], start[a], name, kind)
                steps[a] = h if x + h <= BOUNDS[name][1] else -h
                trial[a] = with_coordinate(params[a], start[a], name, kind, x + steps[a])
            r2 = problem.residuals(trial, mask)
            for a in axes:
                jac[a][:, i] = (r2[a] - res[a]) / steps[a]
        proposal = dict(params)
        for a in axes:
            j, r = jac[a], res[a]
            jtj = j.T @ j
            g = j.T @ r
            damp = lam[a] * np.diag(np.diag(jtj) + 1e-12)
            on = active[a]
            delta = np.zeros(len(coords))
            try:
                delta[on] = -np.linalg.solve((jtj + damp)[np.ix_(on, on)], g[on])
            except np.linalg.LinAlgError:
                pass
            p = params[a]
            for i, (name, kind, _h) in enumerate(coords):
                lo, hi = BOUNDS[name]
                x = min(max(coordinate(p, start[a], name, kind) + delta[i], lo), hi)
                p = with_coordinate(p, start[a], name, kind, x)
            proposal[a] = p
        trial_res = problem.residuals(proposal, mask)
        improved = False
        for a in axes:
            new = float(trial_res[a] @ trial_res[a])
            if new < sse[a]:
                if (sse[a] - new) > 1e-4 * sse[a]:
                    improved = True
                params = {**params, a: proposal[a]}
                res = {**res, a: trial_res[a]}
                sse[a] = new
                lam[a] = max(lam[a] / 4.0, 1e-6)
            else:
                lam[a] = min(lam[a] * 8.0, 1e6)
                improved = improved or lam[a] < 1e6
        if not improved:
            break
    return params, jac, res


def half_intervals(jac: np.ndarray, res: np.ndarray, channels: int = 2) -> np.ndarray:
    """95 % half-intervals of the coordinates from the Gauss-Newton covariance, widened by
    the residuals' integrated autocorrelation time: the replay's floor is smooth in time,
    not white, so n samples carry far fewer than n independent errors."""
    n, p = jac.shape
    s2 = float(res @ res) / max(n - p, 1)
    inflation = 1.0
    for part in np.split(res, channels):   # position, then tacho: one series each
        x = part - part.mean()
        var = float(x @ x)
        if var <= 0.0 or len(x) < 4:
            continue
        tau = 1.0
        for lag in range(1, len(x) // 4):
            rho = float(x[:-lag] @ x[lag:]) / var
            if rho <= 0.05:
                break
            tau += 2.0 * rho
        inflation = max(inflation, tau)
    cov = s2 * inflation * np.linalg.pinv(jac.T @ jac)
    diag = np.diag(cov)
    return 1.96 * np.sqrt(np.where(diag > 0, diag, np.inf))


def scan_mains_phase(problem: Problem, params: dict[str, AxisParams], steps: int = 24) -> None:
    """Stage 0: the mains phase that best replays the first second of the steps: a scan of
    one pulse period, then a golden-section search around the best point of the grid."""
    base = problem.base
    if not any(base.axes[a].converter.kind == "thyristor" for a in AXES):
        return
    p = base.axes["x"].converter.pulse_number
    first = problem.log.experiment_mask("steps")
    first[round(1.2 / base.controller.period):] = False

    def sse(phase: float) -> float:
        problem.mains_phase = phase % (2.0 * math.pi)
        r = problem.residuals(params, first)
        return sum(float(v @ v) for v in r.values())

    step = 2.0 * math.pi / p / steps
    grid = [k * step for k in range(steps)]
    values = [sse(x) for x in grid]
    best = grid[int(np.argmin(values))]
    lo, hi = best - step, best + step
    golden = 0.5 * (math.sqrt(5.0) - 1.0)
    c, d = hi - golden * (hi - lo), lo + golden * (hi - lo)
    fc, fd = sse(c), sse(d)
    for _ in range(6):
        if fc < fd:
            hi, d, fd = d, c, fc
            c = hi - golden * (hi - lo)
            fc = sse(c)
        else:
            lo, c, fc = c, d, fd
            d = lo + golden * (hi - lo)
            fd = sse(d)
    candidates = [(min(values), best), (fc, c), (fd, d)]
    problem.mains_phase = min(candidates)[1] % (2.0 * math.pi)
