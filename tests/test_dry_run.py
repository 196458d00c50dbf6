"""The dry run: the controller's own plan at its own period, against the machine's limits,
without drives or physics; it never trips."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.rrd import assert_verified
from twin.session.dry_run import dry_run
from twin.session.run import RunSpec, run
from twin.session.setup import shipped_program

ENV = {**os.environ, "RERUN_ANALYTICS": "0"}


@pytest.fixture(scope="module")
def square(tmp_path_factory):
    out = tmp_path_factory.mktemp("dry")
    spec = RunSpec(machine="tomsk_xy", program=str(shipped_program("square_circle.ngc")))
    return dry_run(spec, out_dir=out, run_id="dry"), run(spec, out_dir=out, run_id="real",
                                                        rerun="none"), out


def test_the_plan_is_the_real_runs_reference(square):
    planned, real, _ = square
    rec = real.record
    moving = np.flatnonzero(np.hypot(*rec["ref_velocity"].T) > 0)
    assert planned["status"] == "FINISHED"
    # the same planner and interpolator at the same ticks: the same peaks, to the bit
    for k, ax in enumerate("xy"):
        d = planned["axes"][ax]
        assert d["velocity"]["peak"] == pytest.approx(
            np.abs(rec["ref_velocity"][:, k]).max() * 60e3, rel=1e-12)
        assert d["acceleration"]["peak"] == np.abs(rec["ref_acceleration"][:, k]).max()
        assert d["jerk"]["peak"] == np.abs(rec["ref_jerk"][:, k]).max()
    # the cycle time: the reference's end, to the tick (the real run's is measured on the
    # table, which then still settles)
    assert planned["cycle_time_s"] == pytest.approx(rec["t"][moving[-1]], abs=0.0051)
    assert abs(planned["cycle_time_s"] - real.summary["cycle_time_s"]) < 0.05
    assert planned["path_length_mm"] == pytest.approx(real.summary["path_length_mm"],
                                                      rel=1e-6)
    assert planned["over_limits"] == []


def test_the_dry_run_writes_its_record(square):
    planned, _, out = square
    assert json.loads((out / "dry.json").read_text())["cycle_time_s"] == \
        planned["cycle_time_s"]
    assert_verified(out / "dry.rrd", "dry run")


def _twin(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True,
                          text=True, env=ENV, timeout=300)


def test_cli_dry_run_never_trips(tmp_path):
    """It used to run the loop with the drives off: FOLLOWING_ERROR after 0.2 s, exit 1."""
    done = _twin("run", "--dry-run", "--json", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    s = json.loads(done.stdout)
    assert s["dry_run"] and s["status"] == "FINISHED" and s["cycle_time_s"] > 60.0
    done = _twin("jog", "--axis", "y", "--distance", "15", "--dry-run", "--json", "--out",
                 str(tmp_path))
    assert done.returncode == 0, done.stderr
    s = json.loads(done.stdout)
    assert s["commands"] == ["jog y 15 mm"]          # as a person reads it, not in metres
    assert s["path_length_mm"] == pytest.approx(15.0, abs=1e-4)


def test_a_program_that_leaves_the_work_zone_is_refused_naming_its_line(tmp_path):
    prog = tmp_path / "far.ngc"
    prog.write_text("G21 G90\nG1 X10 Y10 F600\nG1 X500\nM30\n")
    done = _twin("run", str(prog), "--dry-run", "--out", str(tmp_path / "runs"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "line 3: the move leaves the work zone X 2 … 298 mm" in done.stderr
