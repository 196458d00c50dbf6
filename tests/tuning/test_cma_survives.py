"""CMA jobs that survive: a job killed with SIGKILL resumes from its JSON-lines trial log
into the very search it was running, losing at most the evaluation in flight; an evaluator
whose worker process dies replaces the pool and finishes the batch."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tuning.evaluator import Evaluator

ENV = {**os.environ, "RERUN_ANALYTICS": "0"}
RUNS = 22                            # two generations of 11: killed inside the second


def _job(out: Path, *more: str, runs: int = RUNS) -> list[str]:
    return [sys.executable, "-m", "twin.cli", "tune", "--method", "cma", "--program", "tiny",
            "--workers", "1", "--seed", "3", "--max-runs", str(runs), "--budget-s", "300",
            "--out", str(out), "--json", *more]


def _niced() -> None:
    """Background work: it must not starve a paced test running beside it in CI."""
    os.nice(19)


def _entries(out: Path) -> list[dict]:
    entries = []
    for line in (out / "cma_trials.jsonl").read_text().splitlines():
        try:
            entries.append(json.loads(line))
        except ValueError:
            pass                      # a torn last line
    return entries


def _points(entries: list[dict]) -> dict[tuple[int, int], tuple]:
    return {(e["generation"], e["index"]): (tuple(e["x"]), e["trial"]["cost"])
            for e in entries}


def test_a_killed_cma_job_resumes_into_the_same_search(tmp_path):
    whole = subprocess.run(_job(tmp_path / "whole"), env=ENV, capture_output=True, text=True,
                           timeout=300, preexec_fn=_niced)
    assert whole.returncode == 0, whole.stderr[-2000:]
    reference = _points(_entries(tmp_path / "whole"))
    assert len(reference) == RUNS

    out = tmp_path / "killed"
    proc = subprocess.Popen(_job(out), env=ENV, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, preexec_fn=_niced)
    try:
        deadline = time.monotonic() + 200.0
        while True:                       # into the second generation
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.05)
            log = out / "cma_trials.jsonl"
            if log.exists() and len(log.read_text().splitlines()) >= 14:
                break
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    kept = _entries(out)
    assert 14 <= len(kept) < RUNS
    resumed = subprocess.run(_job(out, "--resume"), env=ENV, capture_output=True, text=True,
                             timeout=300, preexec_fn=_niced)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    after = _entries(out)
    assert after[:len(kept)] == kept                        # nothing logged was lost
    assert len(after) == RUNS                               # only the rest was run
    assert _points(after) == reference                      # the very same search
    summary = json.loads(resumed.stdout)
    assert summary["runs"] == RUNS
    assert (out / "best.toml").read_bytes() == (tmp_path / "whole" / "best.toml").read_bytes()


def _pool_workers(pid: int) -> list[int]:
    """The job's evaluator processes: its children started by multiprocessing's spawn."""
    children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    out = []
    for child in children:
        try:
            cmdline = Path(f"/proc/{child}/cmdline").read_bytes()
        except OSError:
            continue
        if b"spawn_main" in cmdline:
            out.append(int(child))
    return out


def test_a_job_whose_worker_is_killed_finishes_with_its_outputs(tmp_path):
    """``twin tune --method cma --workers 2``: one evaluator process SIGKILLed mid-run (an
    OOM kill, say). The job replaces it, reruns what it was evaluating and finishes: exit 0,
    ``best.toml`` and ``result.json``, every evaluation logged once."""
    runs = 11                            # one generation: the kill lands inside its batch
    out = tmp_path / "job"
    cmd = _job(out, runs=runs)
    cmd[cmd.index("--workers") + 1] = "2"
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_niced)
    killed = None
    try:
        deadline = time.monotonic() + 200.0
        while killed is None:            # after the first evaluations, inside a batch
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.05)
            log = out / "cma_trials.jsonl"
            if log.exists() and len(log.read_text().splitlines()) >= 3:
                workers = _pool_workers(proc.pid)
                if workers:
                    killed = workers[0]
                    os.kill(killed, signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, stderr[-2000:]
    summary = json.loads(stdout)
    assert summary["runs"] == runs
    assert (out / "best.toml").is_file() and (out / "result.json").is_file()
    entries = _entries(out)
    assert len(entries) == runs                              # each evaluation logged once
    assert len({(e["generation"], e["index"]) for e in entries}) == runs


def test_without_resume_the_log_starts_afresh(tmp_path):
    out = tmp_path / "job"
    out.mkdir()
    (out / "cma_trials.jsonl").write_text('{"generation": 0, "index": 0, "x": [9]}\n')
    done = subprocess.run(_job(out, runs=2), env=ENV, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert len(_entries(out)) == 2 and _entries(out)[0]["x"] != [9]


def test_an_evaluator_whose_worker_dies_finishes_the_batch():
    with Evaluator.create("tomsk_xy", "tiny") as serial:
        xs = [np.full(11, v) for v in (-0.4, -0.2, 0.0, 0.1, 0.2, 0.3)]
        expected = [t.cost for t in serial.evaluate(xs)]
        killed: list[int] = []

        with Evaluator(serial.tuning, workers=2) as ev:
            def kill_one(_k, _trial):
                if not killed:            # after the first result: one worker dies
                    pid = next(iter(ev._pool._processes))
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)

            got = ev.evaluate(xs, on_each=kill_one)
            assert killed
            assert [t.cost for t in got] == expected
            assert len(ev.trials) == len(xs)          # each point recorded once
            assert ev.evaluate(xs[:2]) and len(ev.trials) == len(xs) + 2   # the pool works


@pytest.mark.parametrize("line", ["", "{", '{"generation": 0}', "not json"])
def test_a_torn_or_foreign_line_in_the_log_is_skipped(tmp_path, line):
    from tuning.cma_job import TrialLog

    path = tmp_path / "log.jsonl"
    path.write_text(line + "\n")
    log = TrialLog(path, resume=True)
    log.close()
    assert log.done == {}
