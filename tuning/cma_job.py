"""CMA-ES over the normalised tuning space (``cma`` package), within a wall-time budget.

The search starts at the analytic design (``x = 0``) with step size ``sigma0`` in the
normalised units, bounded to [-1, 1]. A generation is evaluated in parallel by the
``Evaluator``'s workers; no new generation starts when the time left is less than the last
one took.
"""

from __future__ import annotations

import math
import time

import cma
import numpy as np

from tuning.evaluator import Evaluator, Trial
from twin.errors import ConfigError

__all__ = ["run_cma"]


def run_cma(evaluator: Evaluator, *, budget_s: float, max_evals: int | None = None,
            sigma0: float = 0.3, popsize: int | None = None, seed: int = 0) -> Trial:
    """Minimise the tuning cost with CMA-ES; returns the best trial (the baseline if
    nothing beat it).

    Parameters
    ----------
    evaluator : Evaluator
        Objective and history (trials are appended to ``evaluator.trials``).
    budget_s : float
        Wall-time budget (s).
    max_evals : int, optional
        Stop after this many runs as well.
    sigma0 : float
        Initial step size (normalised units).
    popsize : int, optional
        Population size; default CMA's ``4 + 3·ln(n)`` rounded up to a multiple of the
        workers.
    seed : int
        Random seed (the same seed gives the same search).
    """
    if not (math.isfinite(budget_s) and budget_s > 0.0):
        raise ConfigError("budget_s", f"must be a finite number > 0 (s), got {budget_s!r}")
    if not 0.0 < sigma0 <= 1.0:
        raise ConfigError("sigma0", f"must be in (0, 1], got {sigma0!r}")
    n = evaluator.dim
    if popsize is None:
        popsize = 4 + int(3 * math.log(n))
        popsize = -(-popsize // evaluator.workers) * evaluator.workers
    opts = {"bounds": [-1.0, 1.0], "seed": seed + 1, "popsize": popsize, "verbose": -9,
            "tolfun": 1e-4, "tolx": 1e-4}
    es = cma.CMAEvolutionStrategy(np.zeros(n), sigma0, opts)
    start = time.perf_counter()
    last = 0.0
    evals = 0
    while not es.stop():
        left = budget_s - (time.perf_counter() - start)
        if left <= last or (max_evals is not None and evals >= max_evals):
            break
        xs = es.ask()
        if max_evals is not None:
            xs = xs[: max_evals - evals]
        t0 = time.perf_counter()
        trials = evaluator.evaluate(xs)
        last = time.perf_counter() - t0
        evals += len(trials)
        if len(xs) < popsize:
            break
        es.tell(xs, [tr.cost for tr in trials])
    return evaluator.best
