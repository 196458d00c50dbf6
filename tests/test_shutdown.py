"""One shutdown path: Ctrl-C, SIGTERM and SIGHUP stop a run the same way (machine stopped,
summary with a final status, a recording that reads back); the summary is written before the
recording is published; a signal during the writing is held until the record is complete;
a record never says RUNNING."""

from __future__ import annotations

import ctypes
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rerun.chunk as rc

from tests.rrd import assert_verified
from twin.controller.controller import ControllerStatus
from twin.session.run import RunSpec, run
from twin.session.run_end import RunInterrupted, Terminated, final_status
from twin.system.jsonio import json_text
from twin.telemetry.sink import NullSink

# a long dwell: the run is still going when the signal comes (the twin simulates it)
LONG = "G91 G1 X1 Y1 F600\nG4 P3000\nM30\n"


@pytest.mark.parametrize(("signum", "named"), [(signal.SIGTERM, "SIGTERM"),
                                               (signal.SIGHUP, "SIGHUP"),
                                               (signal.SIGINT, "Ctrl-C")])
def test_a_stop_signal_ends_the_run_aborted_with_its_whole_record(signum, named, tmp_path):
    program = tmp_path / "long.ngc"
    program.write_text(LONG)
    out = tmp_path / "runs"
    proc = subprocess.Popen([sys.executable, "-m", "twin.cli", "run", str(program), "--out",
                             str(out), "--json"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "RERUN_ANALYTICS": "0"})
    try:
        deadline = time.monotonic() + 60.0
        while not _loop_under_way(out):
            assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
            assert time.monotonic() < deadline, "the run never started"
            time.sleep(0.05)
        proc.send_signal(signum)
        stdout, stderr = proc.communicate(timeout=60.0)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1, stderr
    printed = json.loads(stdout)
    assert printed["status"] == "ABORTED" and named in printed["aborted"]
    run_id = printed["run_id"]
    written = json.loads((out / f"{run_id}.json").read_text())
    assert written["status"] == "ABORTED" and written["aborted"] == printed["aborted"]
    assert written["controller_status"] == "DWELLING"   # where the signal found it
    assert not list(out.glob("*.partial"))
    chunks = list(rc.RrdReader(out / f"{run_id}.rrd").stream().to_chunks())
    assert chunks, "the recording reads back"


class _OrderSink(NullSink):
    """Checks that the summary exists when the recording is published."""

    def __init__(self, summary: Path, on_finish=None):
        self.summary, self.on_finish, self.calls = summary, on_finish, []

    def finish(self) -> None:
        self.calls.append(("finish", self.summary.exists()))
        if self.on_finish is not None:
            self.on_finish()

    def close(self) -> None:
        self.calls.append(("close", self.summary.exists()))


LOOP_STARTED_BYTES = 1 << 20
"""A ``.rrd.partial`` this large holds telemetry from the loop: the recording's start (name,
blueprint, path frame) is about 140 kB, the first gathered telemetry tens of MB."""


def _loop_under_way(out: Path) -> bool:
    """True once a run writing into ``out`` is in its loop (a stop signal before the loop
    leaves nothing behind and ends the command with 128 + signum)."""
    return any(p.stat().st_size > LOOP_STARTED_BYTES for p in out.glob("*.rrd.partial"))


def test_a_stop_signal_before_the_loop_leaves_nothing_behind(tmp_path, monkeypatch):
    import twin.session.run as run_module

    made = []

    def make_sink_then_signal(*args, **kwargs):
        # the signal comes while the recording is being begun, inside make_sink: the sink
        # never reaches run(), yet its .partial must go
        made.append(run_module.recording_path(args[0], args[1], args[2]))
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):   # the handler runs at the next bytecode boundaries
            pass
        raise AssertionError("the signal was not raised")

    real = run_module.make_sink
    monkeypatch.setattr(run_module, "make_sink",
                        lambda *a, **k: (real(*a, **k), make_sink_then_signal(*a, **k))[0])
    with pytest.raises(Terminated):
        run(RunSpec(builtin="spline_line"), out_dir=tmp_path, run_id="early")
    assert made == [tmp_path / "early.rrd"]
    assert list(tmp_path.iterdir()) == []            # no .partial, no .json, no .rrd
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL   # handlers given back


def test_the_summary_is_written_before_the_recording_is_published(tmp_path):
    sink = _OrderSink(tmp_path / "order.json")
    result = run(RunSpec(builtin="spline_line"), out_dir=tmp_path, run_id="order", sink=sink)
    assert result.summary["status"] == "FINISHED"
    assert sink.calls == [("finish", False), ("close", True)]


def test_a_signal_while_the_record_is_written_waits_for_it(tmp_path):
    sink = _OrderSink(tmp_path / "late.json",
                      on_finish=lambda: os.kill(os.getpid(), signal.SIGTERM))
    with pytest.raises(RunInterrupted) as caught:
        run(RunSpec(builtin="spline_line"), out_dir=tmp_path, run_id="late", sink=sink)
    assert caught.value.signum == signal.SIGTERM
    summary = caught.value.result.summary
    assert summary["status"] == "FINISHED"           # the run itself had ended
    assert json.loads((tmp_path / "late.json").read_text()) == json.loads(json_text(summary))
    assert sink.calls[-1] == ("close", True)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL   # handlers given back


def _signal_inside_a_c_callback(signum: int) -> None:
    """Deliver ``signum`` to this process while Python runs inside a ctypes callback, where
    the exception its handler raises is printed and dropped (as it is when numba compiles a
    kernel and LLVM calls back to write its cache)."""
    def inside() -> None:
        os.kill(os.getpid(), signum)
        for _ in range(1000):   # the handler runs at the next bytecode boundaries
            pass

    ctypes.CFUNCTYPE(None)(inside)()


def test_a_stop_signal_lost_in_a_c_callback_still_stops_the_run(tmp_path, monkeypatch):
    fired: list[float] = []
    lost: list[type] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: lost.append(u.exc_type))
    before = signal.getsignal(signal.SIGINT)   # what this process had (xdist's may differ)

    def progress(t: float, _max_time: float) -> None:
        if not fired:
            fired.append(t)
            _signal_inside_a_c_callback(signal.SIGINT)

    program = tmp_path / "dwell.ngc"
    program.write_text("G4 P600\nM30\n")
    result = run(RunSpec(program=str(program)), out_dir=tmp_path, run_id="lost",
                 rerun="none", progress=progress)
    assert lost == [Terminated]                 # the handler's raise was dropped
    summary = result.summary
    assert summary["status"] == "ABORTED" and summary["aborted"] == "interrupted (Ctrl-C)"
    assert summary["controller_status"] == "DWELLING"
    assert summary["sim_time_s"] <= fired[0] + 0.25 + 1e-9   # at the next checkpoint
    assert signal.getsignal(signal.SIGINT) is before   # the handler given back


_DROP_SIGINT = """
import ctypes, os, signal, sys
from twin.system import interrupts
def drop():
    def inside():
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):
            pass
    ctypes.CFUNCTYPE(None)(inside)()
"""


def test_a_ctrl_c_dropped_while_the_command_imports_ends_it_once_imported():
    """The ``twin`` command's start (``twin.system.interrupts``): a Ctrl-C whose exit an
    import's callback drops is honoured when the imports are done, silently."""
    script = _DROP_SIGINT + """
interrupts.install()
drop()                      # the handler's SystemExit is dropped here
print("went on", flush=True)
interrupts.honour()
print("not reached", flush=True)
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert (proc.returncode, proc.stdout, proc.stderr) == (130, "went on\n", "")


def test_a_ctrl_c_dropped_before_a_run_stops_the_run_before_it_writes(tmp_path):
    """After the imports, a Ctrl-C dropped in a callback before a run begins is raised by
    the run's own handlers as they are installed: nothing is written."""
    program = tmp_path / "dwell.ngc"
    program.write_text("G4 P600\nM30\n")
    out = tmp_path / "runs"
    script = _DROP_SIGINT + f"""
interrupts.install()
interrupts.honour()
from twin.session.run import RunSpec, prepare, run
p = prepare(RunSpec(program={str(program)!r}))
drop()                      # the KeyboardInterrupt is dropped here: not printed
print("went on", flush=True)
try:
    run(RunSpec(program={str(program)!r}), out_dir={str(out)!r}, rerun="file", prepared=p)
except KeyboardInterrupt as exc:
    print(type(exc).__name__, flush=True)
    sys.exit(130)
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "RERUN_ANALYTICS": "0"})
    assert (proc.returncode, proc.stdout, proc.stderr) == (130, "went on\nTerminated\n",
                                                           "")
    assert not out.exists() or not any(out.iterdir())


def test_a_run_cut_by_max_time_says_timeout(tmp_path):
    s = run(RunSpec(max_time=1.0), out_dir=tmp_path, rerun="none").summary
    assert s["status"] == "TIMEOUT" and "max_time (1 s)" in s["timeout"]
    assert s["controller_status"] == "RUNNING"


@pytest.mark.parametrize("status", list(ControllerStatus))
def test_a_record_never_says_a_state_in_progress(status):
    out = final_status(status, None, 10.0)
    assert out["status"] in ("FINISHED", "FAULT", "TIMEOUT")
    assert out["controller_status"] == status.name
    if status >= ControllerStatus.LIMIT_TRIP:
        assert out["status"] == "FAULT" and out["fault"] == status.name
    assert final_status(status, "interrupted (SIGTERM)", 10.0)["status"] == "ABORTED"


@pytest.mark.slow
def test_stop_signals_at_random_instants_of_a_lockstep_run(tmp_path):
    """SIGTERM, SIGINT or SIGHUP at a random instant of a lock-step ``twin run`` (Python
    starting, the plant compiling, the loop, the record being written, after the end): each
    trial leaves nothing under a final name, or a recording that passes ``rerun rrd verify``
    with its summary in a final status. CI runs 6 trials; the full run 30."""
    trials = 6 if os.environ.get("CI") else 30
    rng = random.Random(2319)
    program = tmp_path / "dwell.ngc"
    program.write_text("G91 G1 X2 Y1 F600\nG4 P60\nG1 X-2 Y-1\nM30\n")
    outcomes: dict[str, int] = {}
    for trial in range(trials):
        signum = rng.choice((signal.SIGTERM, signal.SIGINT, signal.SIGHUP))
        delay = rng.uniform(0.0, 6.0)
        out = tmp_path / f"trial{trial}"
        proc = subprocess.Popen([sys.executable, "-m", "twin.cli", "run", str(program),
                                 "--out", str(out), "--json"], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True,
                                env={**os.environ, "RERUN_ANALYTICS": "0"})
        time.sleep(delay)
        if proc.poll() is None:
            proc.send_signal(signum)
        try:
            stdout, stderr = proc.communicate(timeout=60.0)
        finally:
            if proc.poll() is None:
                proc.kill()
        where = f"trial {trial}: {signal.Signals(signum).name} after {delay:.2f} s"
        # Python itself may still be starting (before twin.cli runs): its traceback has no
        # frame of ours; from twin.cli on, a start-up Ctrl-C is quiet
        assert "Traceback" not in stderr or "twin/" not in stderr, f"{where}: {stderr[-3000:]}"
        assert not list(out.glob("*.partial")) if out.exists() else True, where
        recordings = sorted(out.glob("*.rrd")) if out.exists() else []
        summaries = sorted(out.glob("*.json")) if out.exists() else []
        assert [p.stem for p in recordings] == [p.stem for p in summaries], where
        for rrd, js in zip(recordings, summaries, strict=True):
            status = json.loads(js.read_text())["status"]
            assert status in ("FINISHED", "ABORTED", "FAULT", "TIMEOUT"), where
            assert_verified(rrd, where)
            outcomes[status] = outcomes.get(status, 0) + 1
        if not recordings:
            outcomes["nothing"] = outcomes.get("nothing", 0) + 1
        if recordings and stdout.strip():
            assert json.loads(stdout)["status"] == json.loads(summaries[0].read_text())[
                "status"], where
    print(f"{trials} trials: {outcomes}")
    assert sum(outcomes.values()) == trials
