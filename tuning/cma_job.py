"""CMA-ES over the normalised tuning space (``cma`` package), within a wall-time budget.

The search starts at the analytic design (``x = 0``) with step size ``sigma0`` in the
normalised units, bounded to [-1, 1]. A generation is evaluated in parallel by the
``Evaluator``'s workers; no new generation starts when the time left is less than the last
one took.

The trial log (``log``): every evaluation is appended, as it ends, to a JSON-lines file —
generation, index in it, the vector and the whole trial; no pickle. A job killed at any
instant leaves every finished evaluation there (a torn last line is ignored). Resumed
(``resume=True``), the same seeded search is replayed: each generation CMA asks for is
looked up in the log, and only the evaluations it does not hold are run, so a resume loses
at most the evaluations that were in flight and follows the very path the uninterrupted
job would have taken (the runs are deterministic).
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import cma
import numpy as np

from tuning.evaluator import Evaluator, Trial
from twin.errors import ConfigError
from twin.system.jsonio import json_text

__all__ = ["run_cma"]


class TrialLog:
    """The JSON-lines trial log of a CMA job (see the module docstring)."""

    def __init__(self, path: str | Path, *, resume: bool):
        self.path = Path(path)
        self.done: dict[tuple[int, int], tuple[tuple[float, ...], Trial]] = {}
        if resume and self.path.exists():
            for line in self.path.read_text(encoding="utf-8", errors="replace").splitlines():
                try:
                    entry = json.loads(line)
                    t = entry["trial"]
                    trial = Trial(tuple(t["x"]), float(t["cost"]), t["terms"],
                                  {k: (math.nan if v is None else v)
                                   for k, v in t["metrics"].items()}, t["status"],
                                  t["settings"], t["wall_time_s"], t["sim_time_s"])
                    key = (int(entry["generation"]), int(entry["index"]))
                except (ValueError, KeyError, TypeError):
                    continue    # a line torn by the kill
                self.done[key] = (tuple(float(v) for v in entry["x"]), trial)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND
                           | (0 if resume else os.O_TRUNC), 0o644)

    def lookup(self, generation: int, index: int, x: np.ndarray) -> Trial | None:
        """The logged trial of this point, if the log holds it (the same vector)."""
        found = self.done.get((generation, index))
        if found is None or not np.array_equal(np.asarray(found[0]), x):
            return None
        return found[1]

    def append(self, generation: int, index: int, x: np.ndarray, trial: Trial) -> None:
        """One evaluation, written as one line with one ``write`` as it ends."""
        line = json_text({"generation": generation, "index": index,
                          "x": [float(v) for v in x], "trial": trial.to_dict()})
        os.write(self._fd, (line + "\n").encode())   # json_text: one line, no newline

    def close(self) -> None:
        os.close(self._fd)


def run_cma(evaluator: Evaluator, *, budget_s: float, max_evals: int | None = None,
            sigma0: float = 0.3, popsize: int | None = None, seed: int = 0,
            log: str | Path | None = None, resume: bool = False) -> Trial:
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
    log : path, optional
        The trial log (JSON lines), appended to as each evaluation ends.
    resume : bool
        Replay ``log`` into the same seeded search; run only what it does not hold.
        Replayed trials count toward ``max_evals`` and go into ``evaluator.trials`` (not
        through ``on_trial``).
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
    book = None if log is None else TrialLog(log, resume=resume)
    start = time.perf_counter()
    # a generation starts only if one as long as the last fits in what is left of the
    # budget; before the first, one as long as the baseline run for each round of workers
    last = evaluator.baseline.wall_time * math.ceil(popsize / evaluator.workers)
    evals = generation = 0
    try:
        while not es.stop():
            left = budget_s - (time.perf_counter() - start)
            if left <= last or (max_evals is not None and evals >= max_evals):
                break
            xs = es.ask()
            if max_evals is not None:
                xs = xs[: max_evals - evals]
            t0 = time.perf_counter()
            trials = _generation(evaluator, xs, generation, book)
            last = time.perf_counter() - t0
            evals += len(trials)
            generation += 1
            if len(xs) < popsize:
                break
            es.tell(xs, [tr.cost for tr in trials])
    finally:
        if book is not None:
            book.close()
    return evaluator.best


def _generation(evaluator: Evaluator, xs: list[np.ndarray], generation: int,
                book: TrialLog | None) -> list[Trial]:
    """The trials of one generation: the log's where it has them, the rest evaluated (each
    logged as it ends)."""
    if book is None:
        return evaluator.evaluate(xs)
    out: list[Trial | None] = [book.lookup(generation, i, x) for i, x in enumerate(xs)]
    for trial in out:
        if trial is not None:
            evaluator.trials.append(trial)
    todo = [i for i, t in enumerate(out) if t is None]

    def logged(k: int, trial: Trial) -> None:
        i = todo[k]
        book.append(generation, i, xs[i], trial)
        out[i] = trial

    evaluator.evaluate([xs[i] for i in todo], on_each=logged)
    return [t for t in out if t is not None]
