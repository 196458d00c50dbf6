"""Optuna (TPE) over the normalised tuning space, in an RDB storage that jobs share.

The study lives in a database: a SQLite file by default, or any SQLAlchemy URL
(``postgresql://user@host/db``) so that any number of ``twin tune --method optuna`` workers
on any number of hosts join the same study (same ``--storage``, machine and program). The
storage runs a heartbeat: a worker that dies leaves its trial RUNNING only until the grace
period has passed; the next worker to start a trial marks it FAILED and re-enqueues its
parameters (``RetryHeartbeatStaleTrialCallback``), so a killed job loses at most the trial in
flight. Optuna's check passes over a trial that never recorded a heartbeat (a worker killed
between creating the trial and its heartbeat thread's first write, which happens): such a
trial would stay RUNNING for ever, so each job, at its start and after every trial, fails
and re-enqueues those that started more than the grace period ago
(``fail_trials_without_heartbeat``). Every finished trial keeps its cost terms, metrics and
settings as user attributes, so a report can be rebuilt from the database alone.
"""

from __future__ import annotations

import math
import multiprocessing
import time
import warnings
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

import optuna
import sqlalchemy
from optuna.storages import RDBStorage

try:
    from optuna.storages import RetryHeartbeatStaleTrialCallback
except ImportError:  # optuna < 4.9 (pyproject allows >= 4.0)
    from optuna.storages import RetryFailedTrialCallback as RetryHeartbeatStaleTrialCallback

from envs.gain_tuning import Tuning
from tuning.evaluator import Evaluator, Trial
from twin.errors import ConfigError

__all__ = ["default_storage", "fail_trials_without_heartbeat", "open_study", "run_optuna",
           "study_trials"]

HEARTBEAT_S = 5
"""Heartbeat interval of a running trial (s)."""
GRACE_S = 20
"""A RUNNING trial whose heartbeat is older than this is declared dead (s)."""


def default_storage(out_dir: Path) -> str:
    """The default storage URL: ``sqlite:///<out_dir>/optuna.db``."""
    return f"sqlite:///{(Path(out_dir) / 'optuna.db').resolve()}"


def open_storage(url: str, *, heartbeat_s: int = HEARTBEAT_S,
                 grace_s: int = GRACE_S) -> RDBStorage:
    """The study database at ``url`` with the heartbeat and the retry of dead trials."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    with warnings.catch_warnings():   # the heartbeat is "experimental" in optuna 5
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        return RDBStorage(url, heartbeat_interval=heartbeat_s, grace_period=grace_s,
                          heartbeat_stale_trial_callback=RetryHeartbeatStaleTrialCallback(
                              max_retry=2))


def open_study(url: str | RDBStorage, name: str, names: tuple[str, ...], *, seed: int = 0,
               heartbeat_s: int = HEARTBEAT_S, grace_s: int = GRACE_S) -> optuna.Study:
    """Create or load study ``name`` in ``url`` (minimisation, multivariate TPE); an open
    storage is used as it is (its own heartbeat and grace period)."""
    storage = url if isinstance(url, RDBStorage) else open_storage(
        url, heartbeat_s=heartbeat_s, grace_s=grace_s)
    sampler = optuna.samplers.TPESampler(seed=seed, multivariate=True, n_startup_trials=10)
    study = optuna.create_study(storage=storage, study_name=name, direction="minimize",
                                sampler=sampler, load_if_exists=True)
    study.set_user_attr("coordinates", list(names))
    fail_trials_without_heartbeat(study, storage)
    return study


def fail_trials_without_heartbeat(study: optuna.Study, storage: RDBStorage) -> list[int]:
    """Fail the RUNNING trials of ``study`` that started more than the storage's grace period
    ago and never recorded a heartbeat, and hand each to the storage's stale-trial callback
    (the retry), as Optuna does for a trial whose heartbeat went stale. Returns their
    numbers. A live trial records its first heartbeat within milliseconds of starting."""
    grace = storage.grace_period or 2 * (storage.heartbeat_interval or 0)
    now = datetime.now()  # Optuna stamps datetime_start with the local clock too
    old = [t for t in study.get_trials(deepcopy=False,
                                       states=(optuna.trial.TrialState.RUNNING,))
           if t.datetime_start is not None
           and (now - t.datetime_start).total_seconds() > grace]
    if not old:
        return []
    with storage.engine.connect() as conn:   # Optuna's schema: one row per beating trial
        beating = {row[0] for row in conn.execute(
            sqlalchemy.text("SELECT trial_id FROM trial_heartbeats"))}
    study_id = storage.get_study_id_from_name(study.study_name)
    retry = storage.get_heartbeat_stale_trial_callback()
    failed = []
    for t in old:
        trial_id = storage.get_trial_id_from_study_id_trial_number(study_id, t.number)
        if trial_id in beating:
            continue
        try:
            if not storage.set_trial_state_values(trial_id, state=optuna.trial.TrialState.FAIL):
                continue
        except optuna.exceptions.UpdateFinishedTrialError:
            continue   # another worker finished or failed it meanwhile
        failed.append(t.number)
        if retry is not None:
            retry(study, storage.get_trial(trial_id))
    return failed


def _check_after_each_trial(storage: RDBStorage
                            ) -> Callable[[optuna.Study, optuna.trial.FrozenTrial], None]:
    def callback(study: optuna.Study, _trial: optuna.trial.FrozenTrial) -> None:
        fail_trials_without_heartbeat(study, storage)

    return callback


def _params(x: Any, names: tuple[str, ...]) -> dict[str, float]:
    return {n: float(v) for n, v in zip(names, x, strict=True)}


def _seed_baseline(study: optuna.Study, baseline: Trial, names: tuple[str, ...]) -> None:
    """Give a new study the analytic design as its first (already known) trial."""
    if study.trials:
        return
    dist = {n: optuna.distributions.FloatDistribution(-1.0, 1.0) for n in names}
    trial = optuna.trial.create_trial(params=_params(baseline.x, names), distributions=dist,
                                      value=baseline.cost,
                                      user_attrs=_attrs(baseline))
    study.add_trial(trial)


def _attrs(trial: Trial) -> dict[str, Any]:
    d = trial.to_dict()
    return {"terms": d["terms"], "metrics": d["metrics"], "status": d["status"],
            "settings": d["settings"], "wall_time_s": d["wall_time_s"],
            "sim_time_s": d["sim_time_s"]}


def _objective(evaluator: Evaluator, names: tuple[str, ...], end: int | None = None
               ) -> Callable[[optuna.Trial], float]:
    """The objective; with ``end``, a trial numbered ``end`` or above is not run (pruned,
    and this process stops): the storage numbers trials atomically, so every process of a
    job sees the same bound and the job runs at most ``end`` − its first number trials."""
    def objective(trial: optuna.Trial) -> float:
        if end is not None and trial.number >= end:
            trial.study.stop()
            raise optuna.TrialPruned(f"the job's --max-runs is spent (trial {trial.number})")
        x = [trial.suggest_float(n, -1.0, 1.0) for n in names]
        result = evaluator.evaluate([x])[0]
        for key, value in _attrs(result).items():
            trial.set_user_attr(key, value)
        return result.cost

    return objective


def study_trials(study: optuna.Study) -> list[Trial]:
    """The study's finished trials as ``Trial``s, in trial-number order."""
    names = tuple(study.user_attrs.get("coordinates", ()))
    out = []
    for t in study.get_trials(deepcopy=False,
                              states=(optuna.trial.TrialState.COMPLETE,)):
        a = t.user_attrs
        metrics = {k: (math.nan if v is None else v) for k, v in a.get("metrics", {}).items()}
        out.append(Trial(tuple(t.params[n] for n in names), float(t.value), a.get("terms", {}),
                         metrics, a.get("status", ""), a.get("settings", {}),
                         a.get("wall_time_s", 0.0), a.get("sim_time_s", 0.0)))
    return out


def _worker(url: str, name: str, tuning: Tuning, budget_s: float, seed: int,
            end: int | None = None) -> None:
    names = tuning.space.names
    storage = open_storage(url)
    study = open_study(storage, name, names, seed=seed)
    study.optimize(_objective(Evaluator(tuning), names, end), timeout=budget_s,
                   callbacks=[_check_after_each_trial(storage)])


def run_optuna(evaluator: Evaluator, *, storage: str, study_name: str, budget_s: float,
               max_trials: int | None = None, seed: int = 0, heartbeat_s: int = HEARTBEAT_S,
               grace_s: int = GRACE_S) -> list[Trial]:
    """Optimise in ``storage`` for ``budget_s`` seconds; returns all the study's finished
    trials (this job's and earlier or concurrent ones'), the analytic baseline first.

    With ``evaluator.workers`` = N > 1, N - 1 extra processes join the study on this host
    (the evaluator's own pool is not used: each worker runs its trials itself).
    ``max_trials`` bounds the tuning runs of the job, all its processes together.
    """
    if not (math.isfinite(budget_s) and budget_s > 0.0):
        raise ConfigError("budget_s", f"must be a finite number > 0 (s), got {budget_s!r}")
    names = evaluator.tuning.space.names
    db = open_storage(storage, heartbeat_s=heartbeat_s, grace_s=grace_s)
    study = open_study(db, study_name, names, seed=seed)
    _seed_baseline(study, evaluator.baseline, names)
    # --max-runs bounds the job, all its processes together: trial numbers from here on
    end = None if max_trials is None else len(study.trials) + max_trials
    t = evaluator.tuning
    ctx = multiprocessing.get_context("spawn")
    extra = [ctx.Process(target=_worker, daemon=True,
                         args=(storage, study_name, t, budget_s, seed + 1 + i, end))
             for i in range(evaluator.workers - 1)]
    for p in extra:
        p.start()
    local = Evaluator(t, 1, evaluator.on_trial)
    start = time.perf_counter()
    try:
        study.optimize(_objective(local, names, end), timeout=budget_s,
                       n_trials=max_trials, callbacks=[_check_after_each_trial(db)])
    finally:
        for p in extra:
            p.join(timeout=max(1.0, budget_s - (time.perf_counter() - start)) + 60.0)
            if p.is_alive():
                p.terminate()
    evaluator.trials.extend(local.trials)
    return study_trials(study)
