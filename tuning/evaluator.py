"""Evaluate tuning vectors on one machine and program, in one or several worker processes.

Every black-box method sees the same objective: ``cost(x)`` of a normalised vector
``x ∈ [-1, 1]^11`` (``envs.space.TuningSpace``) is the sum of the weighted terms of
``envs.evaluation.cost_terms``, so the analytic design (``x = 0``) costs ``Σ w_i`` and a
failed run costs the penalty. ``Evaluator`` keeps every ``Trial`` in order and the best.
"""

from __future__ import annotations

import math
import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from envs.evaluation import Weights
from envs.gain_tuning import Tuning
from twin.config import MachineConfig, load_machine
from twin.errors import ConfigError

__all__ = ["MAX_POOL_RESTARTS", "Evaluator", "Trial", "baseline_trial"]

MAX_POOL_RESTARTS = 3
"""How often ``Evaluator.evaluate`` replaces a pool that lost a worker, per call."""


@dataclass(frozen=True)
class Trial:
    """One evaluated setting.

    Attributes
    ----------
    x : tuple of float
        The normalised vector (1).
    cost : float
        Sum of ``terms`` (1).
    terms : dict of str to float
        Weighted cost terms (1).
    metrics : dict of str to float
        Run metrics (SI; NaN for a failed run).
    status : str
        Final controller status, or ``"DIVERGED"``.
    settings : dict
        Gains and jerk limit (``TuningSettings.to_dict``, SI).
    wall_time, sim_time : float
        Wall-clock and simulated time of the run (s).
    """

    x: tuple[float, ...]
    cost: float
    terms: dict[str, float]
    metrics: dict[str, float]
    status: str
    settings: dict[str, Any]
    wall_time: float = 0.0
    sim_time: float = 0.0

    @property
    def failed(self) -> bool:
        """The run diverged or tripped."""
        return self.terms.get("failure", 0.0) > 0.0

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict (NaN metrics become None)."""
        return {"x": list(self.x), "cost": self.cost, "terms": self.terms,
                "metrics": {k: (None if math.isnan(v) else v) for k, v in self.metrics.items()},
                "status": self.status, "settings": self.settings,
                "wall_time_s": self.wall_time, "sim_time_s": self.sim_time}


def _trial(tuning: Tuning, x: Sequence[float]) -> Trial:
    settings, outcome, terms = tuning.evaluate(np.asarray(x, dtype=float))
    return Trial(tuple(float(v) for v in x), math.fsum(terms.values()), terms,
                 dict(outcome.metrics), outcome.status, settings.to_dict(),
                 outcome.wall_time, outcome.sim_time)


def baseline_trial(tuning: Tuning) -> Trial:
    """The analytic baseline run of ``tuning`` as a trial (``x = 0``)."""
    dim = tuning.space.dim
    terms = tuning.terms(tuning.baseline)
    return Trial(tuple([0.0] * dim), math.fsum(terms.values()), terms,
                 dict(tuning.baseline.metrics), tuning.baseline.status,
                 tuning.space.decode(np.zeros(dim)).to_dict(), tuning.baseline.wall_time,
                 tuning.baseline.sim_time)


_WORKER: Tuning | None = None


def _init_worker(tuning: Tuning) -> None:
    global _WORKER
    _WORKER = tuning


def _work(x: Sequence[float]) -> Trial:
    if _WORKER is None:
        raise RuntimeError("worker not initialised")
    return _trial(_WORKER, x)


@dataclass
class Evaluator:
    """Runs tuning vectors on ``tuning``'s machine and program and keeps the history.

    Parameters
    ----------
    tuning : Tuning
        The machine, program, space, baseline and cost.
    workers : int
        Worker processes (1: evaluate in this process).
    on_trial : callable(Trial), optional
        Called in this process after each trial.
    """

    tuning: Tuning
    workers: int = 1
    on_trial: Callable[[Trial], None] | None = None
    trials: list[Trial] = field(default_factory=list)
    _pool: ProcessPoolExecutor | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) \
                or self.workers < 1:
            raise ConfigError("workers", f"must be an integer >= 1, got {self.workers!r}")

    @classmethod
    def create(cls, machine: str | MachineConfig, program: str = "compact", *,
               weights: Weights | None = None, penalty: float = 50.0, workers: int = 1,
               on_trial: Callable[[Trial], None] | None = None,
               belief: str | MachineConfig | None = None,
               max_cycle_time_increase: float | None = None) -> Evaluator:
        """Load the machine (and the controller's model of it, ``belief``; default the
        machine), run the analytic baseline and return an evaluator (with the cycle-time
        constraint ``max_cycle_time_increase``, a share, when given)."""
        cfg = machine if isinstance(machine, MachineConfig) else load_machine(machine)
        model = belief if belief is None or isinstance(belief, MachineConfig) \
            else load_machine(belief)
        return cls(Tuning(cfg, program, weights=weights, penalty=penalty, belief=model,
                          max_cycle_time_increase=max_cycle_time_increase),
                   workers, on_trial)

    def settings_trial(self, settings: dict[str, Any], x: Sequence[float]) -> Trial:
        """Run ``settings`` (``TuningSettings.to_dict``, SI) once, in this process, as a
        trial at the normalised vector ``x`` (not recorded among ``trials``)."""
        from envs.space import settings_from_dict

        s = settings_from_dict(settings, self.tuning.space.analytic)
        outcome = self.tuning.run(s)
        terms = self.tuning.terms(outcome)
        return Trial(tuple(float(v) for v in x), math.fsum(terms.values()), terms,
                     dict(outcome.metrics), outcome.status, s.to_dict(), outcome.wall_time,
                     outcome.sim_time)

    def trace(self, settings: dict[str, Any]) -> dict[str, np.ndarray] | None:
        """Run ``settings`` (``TuningSettings.to_dict``, SI) once, in this process, and
        return its errors and path speed against time (``RunOutcome.trace``); None if the
        run failed."""
        from envs.space import settings_from_dict

        outcome = self.tuning.run(settings_from_dict(settings, self.tuning.space.analytic),
                                  trace=True)
        return None if outcome.failed else outcome.trace

    @property
    def dim(self) -> int:
        """Length of a tuning vector."""
        return self.tuning.space.dim

    @property
    def baseline(self) -> Trial:
        """The analytic design as a trial (``x = 0``)."""
        return baseline_trial(self.tuning)

    @property
    def best(self) -> Trial:
        """The cheapest trial so far (the baseline if none is cheaper)."""
        return min([self.baseline, *self.trials], key=lambda tr: tr.cost)

    def evaluate(self, xs: Sequence[Sequence[float]], *,
                 on_each: Callable[[int, Trial], None] | None = None) -> list[Trial]:
        """Evaluate vectors (in parallel with ``workers`` > 1); returns them in order.

        ``on_each(k, trial)`` is called as each evaluation ends (in the order they end). A
        worker process that dies (an OOM kill, say) breaks the pool: a new pool is started
        and the evaluations that had not ended are run again, up to ``MAX_POOL_RESTARTS``
        times; the ones that ended are kept.
        """
        xs = [np.asarray(x, dtype=float) for x in xs]
        out: list[Trial | None] = [None] * len(xs)

        def done(k: int, trial: Trial) -> None:
            out[k] = self._record(trial)
            if on_each is not None:
                on_each(k, trial)

        if self.workers == 1 or len(xs) == 1:
            for k, x in enumerate(xs):
                done(k, _trial(self.tuning, x))
            return out  # type: ignore[return-value]
        for restart in range(MAX_POOL_RESTARTS + 1):
            pool = self._ensure_pool()
            futures = {pool.submit(_work, xs[k]): k for k, t in enumerate(out) if t is None}
            try:
                for future in as_completed(futures):
                    done(futures[future], future.result())
                break
            except BrokenProcessPool:
                self._pool = None          # dead: the next round starts a fresh one
                pool.shutdown(wait=False, cancel_futures=True)
                if restart == MAX_POOL_RESTARTS:
                    raise
        return out  # type: ignore[return-value]

    def _record(self, trial: Trial) -> Trial:
        self.trials.append(trial)
        if self.on_trial is not None:
            self.on_trial(trial)
        return trial

    def _ensure_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            t = self.tuning
            self._pool = ProcessPoolExecutor(
                self.workers, mp_context=multiprocessing.get_context("spawn"),
                initializer=_init_worker, initargs=(t,))
        return self._pool

    def close(self) -> None:
        """Stop the worker processes."""
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

