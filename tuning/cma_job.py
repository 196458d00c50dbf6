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
job would have taken (the runs are deterministic). A line that is not a whole trial — torn
by the kill, or of the wrong shape (a type, a length, nesting deeper than
``twin.nesting.MAX_DEPTH``, a value that is not finite) — is skipped with a warning
naming its line; its evaluation runs again.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cma
import numpy as np

from tuning.evaluator import Evaluator, Trial
from twin.errors import ConfigError
from twin.system.jsonio import json_text, load_json

__all__ = ["run_cma"]


WARNED_LINES = 5
"""Skipped lines of a trial log named one by one; past them, only how many more."""


class TrialLog:
    """The JSON-lines trial log of a CMA job (see the module docstring).

    Parameters
    ----------
    path : path
        The log.
    resume : bool
        Read the trials it holds (else it is started anew).
    dim : int, optional
        Length of the vectors (a line with another is skipped).
    warn : callable(str), optional
        Told about the lines skipped.
    """

    def __init__(self, path: str | Path, *, resume: bool, dim: int | None = None,
                 warn: Callable[[str], None] | None = None):
        self.path = Path(path)
        self.done: dict[tuple[int, int], tuple[tuple[float, ...], Trial]] = {}
        if resume and self.path.exists():
            self._read(dim, warn)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND
                           | (0 if resume else os.O_TRUNC), 0o644)

    def _read(self, dim: int | None, warn: Callable[[str], None] | None) -> None:
        """The trials of the log, line by line; a line that is not one is skipped."""
        skipped: list[str] = []
        with open(self.path, encoding="utf-8", errors="replace") as lines:
            for number, line in enumerate(lines, start=1):
                if not line.strip():
                    continue
                try:
                    key, x, trial = _entry(load_json(line, f"{self.path}, line {number}",
                                                     first_line=number), dim)
                except (ValueError, KeyError, TypeError) as exc:   # ConfigError: too deep
                    reason = (exc.message if isinstance(exc, ConfigError) else
                              f"not JSON: {exc.msg} at column {exc.colno}"
                              if isinstance(exc, json.JSONDecodeError) else
                              f"no {exc}" if isinstance(exc, KeyError) else str(exc))
                    reason = _shorter(reason)
                    skipped.append(reason if reason.startswith(f"line {number},") else
                                   f"line {number} ({reason})")
                    continue
                self.done[key] = (x, trial)
        if skipped and warn is not None:
            more = len(skipped) - WARNED_LINES
            warn(f"{self.path}: skipped {len(skipped)} line{'s' * (len(skipped) > 1)} that "
                 "hold no whole trial (torn by a kill, or altered), run again: "
                 + "; ".join(skipped[:WARNED_LINES]) + (f"; and {more} more" if more > 0
                                                        else ""))

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


def _shorter(text: str, width: int = 120) -> str:
    return text if len(text) <= width else text[:width] + "…"


def _number(value: Any, what: str, *, finite: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"{what} must be a number, got {type(value).__name__}")
    if finite and not math.isfinite(value):
        raise ValueError(f"{what} must be finite, got {value}")
    return float(value)


def _vector(value: Any, what: str, dim: int | None) -> tuple[float, ...]:
    if not isinstance(value, list) or (dim is not None and len(value) != dim):
        raise TypeError(f"{what} must be a list of {dim or 'some'} numbers")
    return tuple(_number(v, what) for v in value)


def _table(value: Any, what: str, *, none_is_nan: bool = False) -> dict[str, float]:
    if not isinstance(value, dict):
        raise TypeError(f"{what} must be an object of numbers")
    return {str(k): math.nan if v is None and none_is_nan else _number(v, f"{what}.{k}")
            for k, v in value.items()}


def _settings(value: Any) -> dict[str, Any]:
    """The settings of a logged trial, in the shape ``TuningSettings.to_dict`` writes."""
    if not isinstance(value, dict):
        raise TypeError("trial.settings must be an object")
    alpha = value["dcu_alpha"]
    if not isinstance(alpha, list) or len(alpha) != 2:
        raise TypeError("trial.settings.dcu_alpha must be a list of two lists")
    return {"kp": list(_vector(value["kp"], "trial.settings.kp", 2)),
            "ki": list(_vector(value["ki"], "trial.settings.ki", 2)),
            "dcu_alpha": [list(_vector(row, "trial.settings.dcu_alpha", None))
                          for row in alpha],
            "max_jerk": _number(value["max_jerk"], "trial.settings.max_jerk")}


def _entry(entry: Any, dim: int | None
           ) -> tuple[tuple[int, int], tuple[float, ...], Trial]:
    """One line of the log read back: (generation, index), the vector, the trial.

    Raises
    ------
    TypeError, ValueError, KeyError
        It is not a trial as ``TrialLog.append`` writes one."""
    if not isinstance(entry, dict) or not isinstance(entry.get("trial"), dict):
        raise TypeError("not a trial object")
    key = (entry["generation"], entry["index"])
    if not all(type(k) is int and 0 <= k < 2**31 for k in key):
        raise ValueError("generation and index must be whole numbers >= 0")
    t = entry["trial"]
    status = t["status"]
    if not isinstance(status, str):
        raise TypeError("trial.status must be a string")
    trial = Trial(_vector(t["x"], "trial.x", dim), _number(t["cost"], "trial.cost"),
                  _table(t["terms"], "trial.terms"),
                  _table(t["metrics"], "trial.metrics", none_is_nan=True), status,
                  _settings(t["settings"]), _number(t["wall_time_s"], "trial.wall_time_s"),
                  _number(t["sim_time_s"], "trial.sim_time_s"))
    return key, _vector(entry["x"], "x", dim), trial


def run_cma(evaluator: Evaluator, *, budget_s: float, max_evals: int | None = None,
            sigma0: float = 0.3, popsize: int | None = None, seed: int = 0,
            log: str | Path | None = None, resume: bool = False,
            warn: Callable[[str], None] | None = None) -> Trial:
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
    warn : callable(str), optional
        Told about the lines of ``log`` skipped on resume.
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
    book = None if log is None else TrialLog(log, resume=resume, dim=n, warn=warn)
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
