"""Optuna jobs in an RDB storage: the study persists, a killed job resumes losing at most the
trial in flight (tested by killing a real ``twin tune`` process), workers share a study."""

import os
import signal
import subprocess
import sys
import time

import optuna
import pytest

from tuning.evaluator import Evaluator
from tuning.optuna_job import open_study, run_optuna, study_trials

STUDY = "kill-test"


def _states(url):
    study = optuna.load_study(study_name=STUDY, storage=url)
    return [t.state for t in study.get_trials(deepcopy=False)], study


def test_killed_job_resumes_losing_at_most_the_trial_in_flight(tmp_path):
    url = f"sqlite:///{tmp_path / 'study.db'}"
    cmd = [sys.executable, "-m", "twin.cli", "tune", "--method", "optuna", "--program",
           "tiny", "--budget-s", "120", "--workers", "1", "--storage", url, "--study", STUDY,
           "--out", str(tmp_path / "job")]
    env = {**os.environ, "RERUN_ANALYTICS": "0"}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 90.0
        while time.monotonic() < deadline:
            time.sleep(0.5)
            try:
                states, _ = _states(url)
            except Exception:  # the job has not created the study yet
                continue
            if states.count(optuna.trial.TrialState.COMPLETE) >= 6:
                break
        else:
            pytest.fail("the job did not finish 6 trials in 90 s")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    states, study = _states(url)
    done_before = {t.number: t.params for t in study.get_trials(deepcopy=False)
                   if t.state == optuna.trial.TrialState.COMPLETE}
    running = [t for t in study.get_trials(deepcopy=False)
               if t.state == optuna.trial.TrialState.RUNNING]
    assert len(running) <= 1           # the one in flight, if the kill caught one
    time.sleep(2.5)                    # past the grace period of the resumed job
    with Evaluator.create("tomsk_xy", "tiny") as ev:
        trials = run_optuna(ev, storage=url, study_name=STUDY, budget_s=60.0, max_trials=3,
                            heartbeat_s=1, grace_s=2)
    study = optuna.load_study(study_name=STUDY, storage=url)
    after = study.get_trials(deepcopy=False)
    for number, params in done_before.items():        # nothing finished was lost
        assert after[number].state == optuna.trial.TrialState.COMPLETE
        assert after[number].params == params
    for t in running:                   # the one in flight failed and was re-enqueued
        assert after[t.number].state == optuna.trial.TrialState.FAIL
        retried = [u for u in after if u.system_attrs.get("failed_trial") == t.number]
        assert retried
        # Optuna stores each parameter as it is drawn, so the kill may catch a trial with only
        # some of them: the retry reuses every one that was drawn and draws the rest afresh.
        assert {k: retried[0].params[k] for k in t.params} == t.params
        assert set(retried[0].params) == set(done_before[next(iter(done_before))])
    assert len(trials) == len(done_before) + 3
    assert all(u.state != optuna.trial.TrialState.RUNNING for u in after)


def test_study_keeps_the_report_data(tmp_path):
    url = f"sqlite:///{tmp_path / 'study.db'}"
    with Evaluator.create("tomsk_xy", "tiny") as ev:
        trials = run_optuna(ev, storage=url, study_name="s", budget_s=60.0, max_trials=4)
        baseline = ev.baseline
    assert len(trials) == 5
    assert trials[0].x == baseline.x and trials[0].cost == baseline.cost   # seeded first
    names = Evaluator.create("tomsk_xy", "tiny").tuning.space.names
    reread = study_trials(open_study(url, "s", names))
    assert [t.cost for t in reread] == [t.cost for t in trials]
    assert reread[1].metrics == trials[1].metrics and reread[1].settings == trials[1].settings


def test_two_workers_share_one_study(tmp_path):
    url = f"sqlite:///{tmp_path / 'study.db'}"
    with Evaluator.create("tomsk_xy", "tiny", workers=2) as ev:
        trials = run_optuna(ev, storage=url, study_name="w", budget_s=10.0)  # time to start
        local = len(ev.trials)
    # the extra worker process added trials of its own to the same study
    assert len(trials) > local + 1


def test_a_trial_that_never_beat_is_failed_and_retried(tmp_path):
    """Optuna's own stale check passes over a RUNNING trial without any heartbeat (its
    worker died between creating it and the heartbeat thread's first write; it happened in
    CI). ``study.ask()`` makes exactly such a trial; past the grace period the next job
    fails it and runs its retry."""
    url = f"sqlite:///{tmp_path / 'study.db'}"
    with Evaluator.create("tomsk_xy", "tiny") as ev:
        names = ev.tuning.space.names
        with pytest.warns(UserWarning, match="Heartbeat"):   # ask() starts no heartbeat
            zombie = open_study(url, "z", names, heartbeat_s=1, grace_s=1).ask()
        young = open_study(url, "z", names, heartbeat_s=1, grace_s=1)
        assert young.trials[zombie.number].state == optuna.trial.TrialState.RUNNING
        time.sleep(1.5)
        run_optuna(ev, storage=url, study_name="z", budget_s=60.0, max_trials=1,
                   heartbeat_s=1, grace_s=1)
    after = optuna.load_study(study_name="z", storage=url).trials
    assert after[zombie.number].state == optuna.trial.TrialState.FAIL
    retried = [t for t in after if t.system_attrs.get("failed_trial") == zombie.number]
    assert len(retried) == 1 and retried[0].state == optuna.trial.TrialState.COMPLETE
    assert all(t.state != optuna.trial.TrialState.RUNNING for t in after)


def test_max_runs_bounds_the_job_across_its_workers(tmp_path):
    url = f"sqlite:///{tmp_path / 'study.db'}"
    with Evaluator.create("tomsk_xy", "tiny", workers=2) as ev:
        trials = run_optuna(ev, storage=url, study_name="m", budget_s=60.0, max_trials=6)
    study = optuna.load_study(study_name="m", storage=url)
    done = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(trials) == len(done) <= 1 + 6          # the seeded baseline + at most 6 runs
    assert len(done) >= 1 + 3                          # and the job did run
    assert all(t.state != optuna.trial.TrialState.RUNNING for t in study.trials)
