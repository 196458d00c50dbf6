"""What the command line says and leaves behind (issue 32): refused input writes nothing,
errors are one plain line naming the option, experiments record like runs, ``twin runs``
reads at 80 columns, ``twin runs diff`` shows two runs side by side."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.rrd import labelled, layout_views
from tests.test_run import _rrd_scalars

TWIN = [sys.executable, "-m", "twin.cli"]
ENV = {**os.environ, "RERUN_ANALYTICS": "0", "MPLBACKEND": "Agg"}
CI = os.environ.get("CI") == "true"
REFUSED = [
    ("jog", "--axis", "x", "--distance", "5000"),          # the work zone, as a program's
    ("compare", "--sweep", "max_jerk=a,b"),
    ("compare", "--sweep", "nosuch=1,2"),
    ("compare", "--profiles", "trapezoid,foo"),
    ("experiment", "step", "--amplitude", "500"),           # beyond the travel
]
"""Refused commands; under CI (a subprocess costs seconds) one of each kind of refusal."""


def _twin(*args: str, cwd: Path | None = None, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([*TWIN, *args], capture_output=True, text=True, timeout=600,
                          env={**ENV, **env}, cwd=cwd)


def _files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*")) if folder.exists() else []


@pytest.mark.parametrize("args", [REFUSED[k] for k in ((0, 1, 4) if CI else range(5))])
def test_refused_input_writes_nothing_and_says_one_line(tmp_path, args):
    out = tmp_path / "out"
    r = _twin(*args, "--out", str(out))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert "(" not in lines[0].split("expected one of")[-1][:2]          # no Python tuple
    assert " m)" not in lines[0] and _files(out) == [], _files(out)


def test_option_checks_read_as_plain_words(tmp_path):
    rng = np.random.default_rng(5)
    for value in rng.integers(4, 1000, 1 if CI else 3):
        r = _twin("run", "--dcu-order", str(value), "--out", str(tmp_path))
        assert r.returncode == 2
        assert r.stderr == f"error: --dcu-order: must be at most 3, got {value}\n"
    r = _twin("run", "--period", "fast", "--out", str(tmp_path))
    assert r.stderr == "error: --period: must be a number, got fast\n"


def test_an_unknown_modbus_host_is_not_found_rather_than_a_timeout(tmp_path):
    r = _twin("run", "--driver", "modbus://no-such-host.invalid:5020", "--out",
              str(tmp_path))
    assert r.returncode == 2
    assert r.stderr.startswith("error: cannot connect to modbus://no-such-host.invalid:5020: "
                               "host 'no-such-host.invalid' not found")


def test_an_experiment_records_its_response_like_a_run(tmp_path):
    r = _twin("experiment", "step", "--axis", "y", "--amplitude", "0.5", "--duration", "0.3",
              "--out", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    summary = json.loads((tmp_path / f"{d['run_id']}.json").read_text())
    assert summary["experiment"] == "step y 0.5 mm, closed loop"
    scalars = _rrd_scalars(d["recording"])
    _, pos = scalars["axes/y/position/actual"]
    assert 0.45 < pos.max() < 0.6                                   # mm, not m
    for view in layout_views(d["recording"]):
        values = np.concatenate([np.ravel(scalars[e.lstrip("/")][1])
                                 for e in view["contents"] if e.lstrip("/") in scalars])
        lo, hi = view["y_range"]
        assert lo <= values.min() and values.max() <= hi and labelled(lo, hi) >= 2
    listed = _twin("runs", str(tmp_path), "--json")
    (row,) = json.loads(listed.stdout)["runs"]
    assert row["complete"] and row["program"] == "step y 0.5 mm, closed loop"


def _summary(run_id: str, rng: np.random.Generator, **spec) -> dict:
    return {"run_id": run_id, "status": "FINISHED", "machine": "tomsk_xy",
            "cycle_time_s": float(rng.uniform(1, 100)),
            "max_contour_error_um": float(rng.uniform(1, 500)),
            "spec": {"program": "a.ngc", "builtin": "default", "profile": None,
                     "overrides": {}, **spec},
            "config": {"name": "tomsk_xy", "controller": {"regulator": {"kp": 1000.0}}}}


def test_runs_diff_shows_figures_and_every_setting_that_differs(tmp_path):
    rng = np.random.default_rng(9)
    a = _summary("20260101-000000-aaaaaa", rng)
    b = _summary("20260101-000001-bbbbbb", rng, profile="cosine",
                 overrides={"controller.regulator.kp": 2000.0})
    b["config"]["controller"]["regulator"]["kp"] = 2000.0
    for s in (a, b):
        (tmp_path / f"{s['run_id']}.json").write_text(json.dumps(s))
    r = _twin("runs", "diff", "20260101-000000", "20260101-000001", "--folder",
              str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert {x["setting"] for x in d["differences"]} == {
        "profile", "overrides.controller.regulator.kp", "controller.regulator.kp"}
    text = _twin("runs", "diff", a["run_id"], b["run_id"], "--folder", str(tmp_path),
                 COLUMNS="80").stdout
    change = b["cycle_time_s"] - a["cycle_time_s"]
    assert f"{change:+.4g}" in text and all(len(line) <= 80 for line in text.splitlines())
    r = _twin("runs", "diff", "nosuch", a["run_id"], "--folder", str(tmp_path))
    assert r.returncode == 2 and r.stderr.startswith("error: nosuch: no such run")


def test_twin_runs_reads_at_80_columns(tmp_path):
    rng = np.random.default_rng(4)
    ids = []
    for k in range(3):
        s = _summary(f"20260101-00000{k}-{k:06d}", rng, program=None, builtin="none",
                     commands=[f"jog x {rng.uniform(1, 9000):.15g} mm"])
        if k == 1:
            s.update(status="ABORTED", aborted="PlanningError: the move leaves the work "
                     "zone X 2 … 298 mm, Y 2 … 198 mm (it spans X 10 … 5010, Y 10 … 10 mm)")
        (tmp_path / f"{s['run_id']}.json").write_text(json.dumps(s))
        ids.append(s["run_id"])
    text = _twin("runs", str(tmp_path), COLUMNS="80").stdout
    lines = text.splitlines()
    assert all(len(line) <= 80 for line in lines), text
    for run_id in ids:                                  # whole, on the row of its run
        assert any(line.lstrip().startswith(run_id) for line in lines), run_id
    start = next(k for k, line in enumerate(lines) if "aborted: PlanningError" in line)
    assert len(lines) - start <= 3                      # the reason: a few lines, not 16
    assert len(lines) <= 16
