"""The ``twin`` command as a user runs it: a real subprocess, real files."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rerun.chunk as rc

TWIN = [sys.executable, "-m", "twin.cli"]
ENV = {**os.environ, "RERUN_ANALYTICS": "0", "COLUMNS": "200"}


def twin(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([*TWIN, *args], capture_output=True, text=True, env=ENV,
                          timeout=timeout)


COMMANDS = {"run", "demo", "view", "machines", "experiment", "home", "jog", "hil-server",
            "compare", "tune", "identify", "runs", "measure", "shaper"}


def test_help_lists_every_command():
    """The Commands panel of ``twin --help``, read row by row (a word that only appears in
    some description, like "run" in "Run a program", does not count): exactly the
    commands the README documents."""
    out = twin("--help").stdout
    panel = out[out.index("Commands"):]
    listed = set(re.findall(r"^│ ([a-z][a-z-]*)\s{2,}\S", panel, flags=re.MULTILINE))
    assert listed == COMMANDS


def test_run_json_prints_exactly_one_object(tmp_path):
    r = twin("run", "twin/programs/square_circle.ngc", "--out", str(tmp_path), "--json",
             "--rerun", "none")
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1
    d = json.loads(lines[0])
    for key in ("cycle_time_s", "path_length_mm", "max_contour_error_um",
                "rms_contour_error_um", "max_coordinate_error_um", "max_velocity_error_um_s",
                "settling_travel_um", "sim_time_s", "wall_time_s", "real_time_factor",
                "recording", "ticks"):
        assert key in d, key
    assert set(d["ticks"]) >= {"due", "on_time", "late", "jitter_p99_us"}
    # 40 mm square + a 20 mm radius circle + the rapids.
    assert d["path_length_mm"] == pytest.approx(4 * 40 + 2 * 3.14159265 * 20 + 20 * 2**0.5
                                                + 20 * 2**0.5, rel=1e-6)


def test_gcode_error_stops_before_motion_with_line_and_column(tmp_path):
    prog = tmp_path / "bad.ngc"
    prog.write_text("G21 G90\nG1 X10 Y10 F600\nG1 X20 Q5 F600\n")
    r = twin("run", str(prog), "--out", str(tmp_path / "runs"))
    assert r.returncode == 2
    assert "line 3, col 8" in r.stderr
    assert not (tmp_path / "runs").exists() or not list((tmp_path / "runs").glob("*.rrd"))


def test_unknown_set_key_names_the_valid_ones(tmp_path):
    r = twin("run", "--set", "kpp=3", "--out", str(tmp_path))
    assert r.returncode == 2
    assert "kpp" in r.stderr and "kp" in r.stderr and "dcu_order" in r.stderr


def test_ctrl_c_leaves_a_readable_recording_and_summary(tmp_path):
    # A move, then a dwell of 600 simulated seconds (about 12 s of wall time).
    prog = tmp_path / "dwell.ngc"
    prog.write_text("G21 G91\nG1 X5 F600\nG4 P600\nM30\n")
    proc = subprocess.Popen([*TWIN, "run", str(prog), "--machine", "laser_belt", "--out",
                             str(tmp_path)], env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    # Wait until the loop is under way (its .rrd.partial has grown past the recording's
    # start, about 140 kB, with the first gathered telemetry, tens of MB after 2 s of wall
    # time), then interrupt it. A signal before the loop leaves nothing and exits 130.
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        partial = list(tmp_path.glob("*.rrd.partial"))
        if partial and partial[0].stat().st_size > 1 << 20:
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 1, stderr
    summaries = list(tmp_path.glob("*.json"))
    assert len(summaries) == 1, stderr
    s = json.loads(summaries[0].read_text())
    assert "interrupted" in s["aborted"]
    assert 0 < s["sim_time_s"] < 600
    rrd = Path(s["recording"])
    assert rrd.exists() and not list(tmp_path.glob("*.partial"))
    entities = {c.entity_path for c in rc.RrdReader(rrd).stream().to_chunks()}
    assert "/axes/x/position/actual" in entities


def test_jog_outside_the_work_zone_is_refused_before_motion(tmp_path):
    r = twin("jog", "--axis", "x", "--distance", "500", "--out", str(tmp_path), "--json")
    assert r.returncode == 2
    assert "work zone" in r.stderr


def test_jog_inside_the_work_zone(tmp_path):
    r = twin("jog", "--axis", "y", "--distance", "12.5", "--out", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["status"] == "FINISHED"
    # home keyframe y = 10 mm; 1 µm is 5 encoder counts.
    assert d["final_position_mm"]["y"] == pytest.approx(22.5, abs=2e-3)
    # a manual move has no programmed path: the summary gives how far the reference went
    # and for how long it moved (it gave 0 mm and 0 s)
    assert d["path_length_mm"] == pytest.approx(12.5, abs=1e-3)
    assert 0.5 < d["cycle_time_s"] < d["sim_time_s"]


def test_end_switch_trips_the_drive_and_keeps_the_record(tmp_path):
    r = twin("jog", "--axis", "x", "--distance", "-20", "--ignore-soft-limits",
             "--out", str(tmp_path), "--json")
    assert r.returncode == 1
    d = json.loads(r.stdout)
    assert d["status"] == "FAULT" and d["fault"] == "LIMIT_TRIP"
    assert Path(d["recording"]).exists()
    assert d["final_position_mm"]["x"] < 2.5           # stopped near the 2 mm switch


def test_home_finds_the_switch(tmp_path):
    r = twin("home", "--axes", "xy", "--out", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["status"] in ("FINISHED", "IDLE")


def test_experiment_open_loop_step(tmp_path):
    r = twin("experiment", "step", "--axis", "x", "--amplitude", "1", "--open-loop",
             "--duration", "0.5", "--json", "--rerun", str(tmp_path / "step.rrd"))
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    # 1 V → ω = 1/K_C → 1/0.04775 · 6e-3/(2π·12) m/s.
    assert d["final_value"] == pytest.approx(1 / 0.04775 * 6e-3 / (2 * 3.14159265 * 12) * 1e6,
                                             rel=0.02)
    assert 0.0 < d["overshoot_percent"] < 15.0
    assert (tmp_path / "step.rrd").exists()
