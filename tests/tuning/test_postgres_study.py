"""Distributed Optuna studies on a real PostgreSQL server (started by ``postgres.py`` in a
temporary directory and stopped afterwards): ``twin tune --worker`` processes sharing one
study, a worker killed with SIGKILL mid-trial, a worker that comes late, and the refusals
of bad storage URLs, credentials and studies, which write nothing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import optuna
import pytest

from tests.tuning.postgres import PASSWORD, postgres_server
from tuning.study_storage import storage_url

COMPLETE, FAIL, RUNNING, WAITING = (optuna.trial.TrialState.COMPLETE,
                                    optuna.trial.TrialState.FAIL,
                                    optuna.trial.TrialState.RUNNING,
                                    optuna.trial.TrialState.WAITING)
ENV = {**os.environ, "RERUN_ANALYTICS": "0"}


@pytest.fixture(scope="module")
def server():
    with postgres_server() as s:
        yield s


def _worker(url: str, study: str, out: Path, *more: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "twin.cli", "tune", "--worker", "--program", "tiny",
           "--storage", url, "--study", study, "--heartbeat-s", "1", "--grace-s", "3",
           "--budget-s", "240", "--out", str(out), "--json", *more]
    # niced: three CPU-bound workers on a 2-core CI machine must not starve a paced test
    # running beside them (a HIL run lost 6 periods in a row to them once). Not to 19: at
    # that weight a long CPU-bound test beside them (the full black-box tuning test of
    # `make test`, 9 minutes on two processes) left them no CPU, and they ran out of time.
    return subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=lambda: os.nice(10))


def _finish(procs: list[subprocess.Popen], timeout: float = 600.0) -> list[tuple[int, str]]:
    """Wait for the workers (``timeout``: a hang guard, far above their budget of 240 s:
    niced, they may wait for the CPU behind a long test beside them)."""
    out = []
    for p in procs:
        try:
            _, err = p.communicate(timeout=timeout)
        finally:
            if p.poll() is None:
                p.kill()
        out.append((p.returncode, err))
    return out


def _trials(url: str, study: str) -> list[optuna.trial.FrozenTrial]:
    return optuna.load_study(study_name=study, storage=storage_url(url)).get_trials(
        deepcopy=False)


def _kill_inside_a_trial(victim: subprocess.Popen, url: str, study: str, *, complete: int,
                         timeout: float) -> list[int]:
    """SIGKILL ``victim`` while it is inside a trial, once ``complete`` trials are done;
    returns the numbers of its RUNNING trials at that instant.

    The victim is stopped (SIGSTOP) before the trials are read for the last time, so the
    trial it is found in cannot finish between that read and the kill; were it read
    running and then killed, it could have completed in between (it did once in CI), and
    no trial would be lost. If the frozen victim is not
    inside a trial after all, it goes on (SIGCONT) and the watch goes on."""
    deadline = time.monotonic() + timeout

    def running_in(trials: list[optuna.trial.FrozenTrial]) -> list[int]:
        return [t.number for t in trials if t.state == RUNNING
                and t.user_attrs.get("worker", "").endswith(f":{victim.pid}")]

    while True:
        assert time.monotonic() < deadline, "the victim never ran a trial"
        assert victim.poll() is None, victim.communicate()[1][-2000:]
        time.sleep(0.1)
        try:
            trials = _trials(url, study)
        except KeyError:
            continue
        if sum(t.state == COMPLETE for t in trials) < complete or not running_in(trials):
            continue
        victim.send_signal(signal.SIGSTOP)          # frozen: its trials cannot change now
        mine = running_in(_trials(url, study))
        if mine:
            victim.send_signal(signal.SIGKILL)
            return mine
        victim.send_signal(signal.SIGCONT)


def _no_duplicates(trials: list[optuna.trial.FrozenTrial]) -> None:
    """Every finished point was run once, but for the retry of a failed trial."""
    complete = [t for t in trials if t.state == COMPLETE]
    points = [tuple(sorted(t.params.items())) for t in complete]
    assert len(set(points)) == len(points), "a point was run twice"


def test_three_workers_run_one_study_to_its_budget_and_agree_on_the_best(server, tmp_path):
    url = server.create_database("three")
    runs = 8
    procs = [_worker(url, "s", tmp_path / f"w{k}", "--max-runs", str(runs)) for k in range(3)]
    for code, err in _finish(procs):
        assert code == 0, err[-2000:]
    trials = _trials(url, "s")
    assert sum(t.state == COMPLETE for t in trials) == runs + 1     # the baseline + 8
    assert not [t for t in trials if t.state in (RUNNING, WAITING, FAIL)]
    _no_duplicates(trials)
    best = {(tmp_path / f"w{k}" / "best.toml").read_bytes() for k in range(3)}
    assert len(best) == 1, "the workers wrote different best settings"
    # a worker that comes after the budget is spent: no trial, the same best, exit 0. (Not
    # timed: with nothing RUNNING it has nothing to wait for, and a late worker niced beside
    # a long CPU-bound test took 83 s to start, run the analytic baseline and leave.)
    ((code, err),) = _finish([_worker(url, "s", tmp_path / "late")])
    assert code == 0, err[-2000:]
    assert len(_trials(url, "s")) == len(trials)
    assert (tmp_path / "late" / "best.toml").read_bytes() in best


def test_a_worker_killed_mid_trial_loses_only_that_trial(server, tmp_path):
    url = server.create_database("killed")
    runs = 24      # enough that the victim is still inside a trial once 3 are complete
    procs = [_worker(url, "k", tmp_path / f"w{k}", "--max-runs", str(runs)) for k in range(3)]
    victim = procs[0]
    mine = _kill_inside_a_trial(victim, url, "k", complete=3, timeout=180.0)
    results = _finish(procs)
    assert results[0][0] == -signal.SIGKILL
    for code, err in results[1:]:
        assert code == 0, err[-2000:]
    trials = _trials(url, "k")
    failed = [t for t in trials if t.state == FAIL]
    assert [t.number for t in failed] == mine                     # the victim's trial only
    retried = [t for t in trials if t.system_attrs.get("failed_trial") == failed[0].number]
    assert len(retried) == 1 and retried[0].state == COMPLETE
    assert retried[0].params == failed[0].params or set(failed[0].params) < set(
        retried[0].params)                                  # the same point, run again
    assert sum(t.state == COMPLETE for t in trials) == runs + 1  # nothing else was lost
    assert not [t for t in trials if t.state in (RUNNING, WAITING)]
    _no_duplicates(trials)


def _refused(args: list[str], tmp_path: Path) -> str:
    out = tmp_path / "job"
    done = subprocess.run([sys.executable, "-m", "twin.cli", "tune", *args, "--out", str(out)],
                          env=ENV, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert not out.exists(), "a refused job wrote files"
    assert "Traceback" not in done.stderr
    return " ".join(done.stderr.split())


def test_an_unreachable_server_is_refused_naming_the_url_without_its_password(tmp_path):
    import socket

    with socket.socket() as s:                        # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"postgresql://twin:{PASSWORD}@127.0.0.1:{port}/tune"
    text = _refused(["--method", "optuna", "--program", "tiny", "--storage", url], tmp_path)
    assert f"postgresql://twin:***@127.0.0.1:{port}/tune" in text
    assert "storage" in text and PASSWORD not in text


def test_wrong_credentials_are_refused_naming_the_url_without_the_password(server, tmp_path):
    url = server.url(password="not-the-password")
    text = _refused(["--method", "optuna", "--program", "tiny", "--storage", url], tmp_path)
    assert "password authentication failed" in text
    assert f"twin:***@127.0.0.1:{server.port}/tune" in text
    assert "not-the-password" not in text


@pytest.mark.parametrize("url", ["postgresq://twin:pw@127.0.0.1/tune",
                                 "mysql://twin:pw@127.0.0.1/tune", "not a url"])
def test_a_malformed_or_unsupported_url_is_refused(url, tmp_path):
    text = _refused(["--method", "optuna", "--program", "tiny", "--storage", url], tmp_path)
    assert "storage" in text and ":pw@" not in text


def test_the_storage_comes_from_the_environment_too(server, tmp_path):
    url = server.url(password="wrong")
    out = tmp_path / "job"
    done = subprocess.run([sys.executable, "-m", "twin.cli", "tune", "--method", "optuna",
                           "--program", "tiny", "--out", str(out)],
                          env={**ENV, "TWIN_TUNE_STORAGE": url}, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and "twin:***@" in " ".join(done.stderr.split())


def test_a_study_of_another_machine_or_program_is_refused(server, tmp_path):
    url = server.create_database("other")
    ((code, err),) = _finish([_worker(url, "shared", tmp_path / "first", "--max-runs", "1")])
    assert code == 0, err[-2000:]
    for args, differs in ((["--machine", "laser_belt", "--program", "tiny"], "machine"),
                          (["--program", "corner"], "program")):
        text = _refused(["--method", "optuna", *args, "--storage", url, "--study", "shared"],
                        tmp_path)
        assert "study 'shared'" in text and differs in text and "tunes something else" in text
        assert f"twin:***@127.0.0.1:{server.port}" in text


def test_a_worker_of_a_study_without_a_budget_is_told_to_give_one(server, tmp_path):
    url = server.create_database("nobudget")
    ((code, err),) = _finish([_worker(url, "n", tmp_path / "w")])
    assert code == 2 and "--max-runs" in " ".join(err.split())
