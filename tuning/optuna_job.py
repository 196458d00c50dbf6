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

A study knows what it tunes: the machine (name and configuration hash), the controller's
model, the program, the cost weights and the coordinates are user attributes written when
it is created, and a job that opens it for anything else is refused (``ConfigError`` naming
the study and the storage, its password masked), as is a storage that cannot be reached.

Workers (``run_worker``, ``twin tune --worker``) share a study's *run budget*, stored with
it when it is created: the baseline plus N tuning runs. A trial runs only while fewer than
the budget's trials are complete, running or waiting before it (trial numbers are handed
out atomically by the database, so workers agree without talking to each other); a trial
that failed (its worker died) no longer counts, and its retry takes its place. A worker
stops when the budget is spent and nothing is left running or waiting, so every worker then
sees the same finished study and writes the same best settings.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import socket
import time
import zlib
from collections.abc import Callable
from datetime import datetime
from typing import Any

import optuna
import sqlalchemy
from optuna.storages import RDBStorage

from envs.gain_tuning import Tuning
from tuning.evaluator import Evaluator, Trial
from tuning.study_storage import (
    GRACE_S,
    HEARTBEAT_S,
    check_identity,
    masked,
    open_storage,
    study_identity,
)
from twin.errors import ConfigError

__all__ = ["fail_trials_without_heartbeat", "open_study", "physical_values", "run_optuna",
           "run_worker", "study_trials"]

WORKER = f"{socket.gethostname()}:{os.getpid()}"
"""This process, as a trial's ``worker`` attribute names it (host and pid)."""

def _identity(tuning: Tuning) -> dict[str, Any]:
    return study_identity(tuning.cfg, tuning.belief, tuning.program, tuning.weights,
                          tuning.max_cycle_time_increase)


def open_study(url: str | RDBStorage, name: str, names: tuple[str, ...], *, seed: int = 0,
               heartbeat_s: int = HEARTBEAT_S, grace_s: int = GRACE_S,
               identity: dict[str, Any] | None = None, budget: int | None = None,
               baseline: Trial | None = None) -> optuna.Study:
    """Create or load study ``name`` in ``url`` (minimisation, multivariate TPE); an open
    storage is used as it is (its own heartbeat and grace period).

    ``identity`` (``study_identity``) is stored with a new study and checked against an
    existing one; ``budget`` (trials: the baseline plus the tuning runs) is stored with a new
    study, which keeps it for every worker; ``baseline`` becomes the first trial of a study
    this call created (the one creator among workers that start together).

    Raises
    ------
    ConfigError
        (field ``study``) The study tunes something else.
    """
    storage = url if isinstance(url, RDBStorage) else open_storage(
        url, heartbeat_s=heartbeat_s, grace_s=grace_s)
    sampler = optuna.samplers.TPESampler(seed=seed, multivariate=True, n_startup_trials=10)
    try:   # exactly one of the workers that start a study at once creates it
        study = optuna.create_study(storage=storage, study_name=name, direction="minimize",
                                    sampler=sampler)
        created = True
    except optuna.exceptions.DuplicatedStudyError:
        study = optuna.load_study(storage=storage, study_name=name, sampler=sampler)
        created = False
    stored = study.user_attrs
    found = stored.get("identity")
    check_identity(found, identity, name, storage)
    if identity is not None and found is None:
        study.set_user_attr("identity", identity)
    if "coordinates" not in stored:
        study.set_user_attr("coordinates", list(names))
    if budget is not None and "budget" not in stored:
        study.set_user_attr("budget", int(budget))
    if created and baseline is not None:
        _seed_baseline(study, baseline, names)
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


def physical_values(settings: dict[str, Any]) -> dict[str, float]:
    """A trial's settings as flat, named values in their units (``kp_x [V/m]``,
    ``max_jerk [m/s³]``): the study's parameters are the normalised coordinates the search
    moves in, so optuna-dashboard shows these user attributes for the gains themselves."""
    out = {}
    for k, ax in enumerate("xy"):
        out[f"kp_{ax} [V/m]"] = float(settings["kp"][k])
        out[f"ki_{ax} [V/(m·s)]"] = float(settings["ki"][k])
        for j, alpha in enumerate(settings["dcu_alpha"][k], start=1):
            out[f"dcu_alpha{j}_{ax} [V/m]"] = float(alpha)
    out["max_jerk [m/s³]"] = float(settings["max_jerk"])
    return out


def _attrs(trial: Trial) -> dict[str, Any]:
    d = trial.to_dict()
    return {"terms": d["terms"], "metrics": d["metrics"], "status": d["status"],
            "settings": d["settings"], "wall_time_s": d["wall_time_s"],
            "sim_time_s": d["sim_time_s"], **physical_values(d["settings"])}


def _objective(evaluator: Evaluator, names: tuple[str, ...], end: int | None = None,
               deadline: float | None = None) -> Callable[[optuna.Trial], float]:
    """The objective (each trial notes the host and process that runs it, user attribute
    ``worker``); with ``end``, a trial numbered ``end`` or above is not run (pruned,
    and this process stops): the storage numbers trials atomically, so every process of a
    job sees the same bound and the job runs at most ``end`` − its first number trials.
    With ``deadline`` (``time.time()`` seconds), a trial starts only if one as long as this
    process's last (at first: the baseline run) ends before it; otherwise this process
    stops: Optuna's own timeout lets the trial in flight overrun the budget."""
    last = [evaluator.baseline.wall_time]

    def objective(trial: optuna.Trial) -> float:
        if end is not None and trial.number >= end:
            trial.study.stop()
            raise optuna.TrialPruned(f"the job's --max-runs is spent (trial {trial.number})")
        if deadline is not None and time.time() + last[0] > deadline:
            trial.study.stop()
            raise optuna.TrialPruned("the job's time budget is spent")
        trial.set_user_attr("worker", WORKER)
        x = [trial.suggest_float(n, -1.0, 1.0) for n in names]
        t0 = time.perf_counter()
        result = evaluator.evaluate([x])[0]
        last[0] = time.perf_counter() - t0
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
            end: int | None = None, deadline: float | None = None) -> None:
    names = tuning.space.names
    storage = open_storage(url)
    study = open_study(storage, name, names, seed=seed, identity=_identity(tuning))
    study.optimize(_objective(Evaluator(tuning), names, end, deadline), timeout=budget_s,
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
    study = open_study(db, study_name, names, seed=seed, identity=_identity(evaluator.tuning))
    _seed_baseline(study, evaluator.baseline, names)
    # --max-runs bounds the job, all its processes together: trial numbers from here on
    end = None if max_trials is None else len(study.trials) + max_trials
    t = evaluator.tuning
    deadline = time.time() + budget_s
    ctx = multiprocessing.get_context("spawn")
    extra = [ctx.Process(target=_worker, daemon=True,
                         args=(storage, study_name, t, budget_s, seed + 1 + i, end, deadline))
             for i in range(evaluator.workers - 1)]
    for p in extra:
        p.start()
    local = Evaluator(t, 1, evaluator.on_trial)
    start = time.perf_counter()
    try:
        study.optimize(_objective(local, names, end, deadline), timeout=budget_s,
                       n_trials=max_trials, callbacks=[_check_after_each_trial(db)])
    finally:
        for p in extra:
            p.join(timeout=max(1.0, budget_s - (time.perf_counter() - start)) + 60.0)
            if p.is_alive():
                p.terminate()
    evaluator.trials.extend(local.trials)
    return study_trials(study)


_LIVE = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.RUNNING,
         optuna.trial.TrialState.WAITING)
"""Trial states that hold a place in a study's run budget."""


def _within_budget(evaluator: Evaluator, names: tuple[str, ...], budget: int
                   ) -> Callable[[optuna.Trial], float]:
    """The objective of a worker: a trial runs only while fewer than ``budget`` trials are
    live (complete, running, waiting) before it; otherwise it is pruned, unrun."""
    run = _objective(evaluator, names)

    def objective(trial: optuna.Trial) -> float:
        ahead = sum(1 for t in trial.study.get_trials(deepcopy=False)
                    if t.number < trial.number and t.state in _LIVE)
        if ahead >= budget:
            raise optuna.TrialPruned(f"the study's budget of {budget} trials is spent")
        return run(trial)

    return objective


def run_worker(evaluator: Evaluator, *, storage: str, study_name: str, budget_s: float,
               max_trials: int | None = None, seed: int = 0, heartbeat_s: int = HEARTBEAT_S,
               grace_s: int = GRACE_S, poll_s: float = 1.0) -> list[Trial]:
    """Join study ``study_name`` in ``storage`` and run its trials until its run budget is
    spent and nothing is left running or waiting (or ``budget_s`` of wall time has passed);
    returns the study's finished trials, the baseline first.

    The first worker creates the study with its budget, ``max_trials`` tuning runs after the
    analytic baseline; a worker that joins an existing study takes the study's budget
    (``max_trials``, if given, must agree). A worker waits for the trials others are still
    running, and fails and re-runs those whose worker died (heartbeat), so that when it
    stops the study is finished, whichever worker stops last.

    Raises
    ------
    ConfigError
        The storage cannot be opened, the study tunes something else, it has no budget and
        none was given, or a different one was.
    """
    if not (math.isfinite(budget_s) and budget_s > 0.0):
        raise ConfigError("budget_s", f"must be a finite number > 0 (s), got {budget_s!r}")
    names = evaluator.tuning.space.names
    db = open_storage(storage, heartbeat_s=heartbeat_s, grace_s=grace_s)
    # workers a scheduler starts with one command line must not draw the same points: the
    # sampler's seed is this one's, salted with the host and process
    salt = zlib.crc32(WORKER.encode())
    study = open_study(db, study_name, names, seed=(seed * 1_000_003 + salt) % 2**32,
                       identity=_identity(evaluator.tuning),
                       budget=None if max_trials is None else max_trials + 1,
                       baseline=evaluator.baseline)
    total = study.user_attrs.get("budget")
    if total is None:
        raise ConfigError("max_runs", f"study {study_name!r} in {masked(storage)} has no run "
                          "budget: give the first worker --max-runs")
    if max_trials is not None and total != max_trials + 1:
        raise ConfigError("max_runs", f"study {study_name!r} in {masked(storage)} has a "
                          f"budget of {total - 1} runs, not {max_trials}")
    local = Evaluator(evaluator.tuning, 1, evaluator.on_trial)
    objective = _within_budget(local, names, total)
    checks = [_check_after_each_trial(db)]
    deadline = time.monotonic() + budget_s
    while time.monotonic() < deadline:
        trials = study.get_trials(deepcopy=False)
        live = sum(1 for t in trials if t.state in _LIVE)
        waiting = any(t.state == optuna.trial.TrialState.WAITING for t in trials)
        if live < total or waiting:
            study.optimize(objective, n_trials=1, callbacks=checks)
            continue
        if not any(t.state == optuna.trial.TrialState.RUNNING for t in trials):
            break                                   # spent, and nothing left in flight
        time.sleep(poll_s)                          # others' trials: finished, or dead
        optuna.storages.fail_stale_trials(study)
        fail_trials_without_heartbeat(study, db)
    evaluator.trials.extend(local.trials)
    return study_trials(study)
