"""``twin runs``: a folder's runs listed with their status and figures, incomplete ones
marked, their leftovers removed with ``--clean`` (after asking, or with ``--yes``), and a
run in progress left alone."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from twin.session.folder import LIVE_S, clean, inventory
from twin.session.run import RunSpec, run


def _twin(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True,
                          text=True, timeout=120, input=stdin,
                          env={**os.environ, "RERUN_ANALYTICS": "0", "COLUMNS": "200"})


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Two complete runs, then the leftovers of three broken ones."""
    out = tmp_path_factory.mktemp("runs")
    run(RunSpec(builtin="spline_line"), out_dir=out, run_id="a-good")
    run(RunSpec(builtin="spline_line", max_time=0.5), out_dir=out, run_id="b-timeout")
    old = time.time() - 2 * LIVE_S
    (out / "c-killed.rrd.partial").write_bytes(b"x")            # a killed run
    (out / "d-nosummary.rrd").write_bytes((out / "a-good.rrd").read_bytes())
    (out / "e-live.rrd.partial").write_bytes(b"x")              # a run still going
    for name in ("c-killed.rrd.partial", "d-nosummary.rrd"):
        os.utime(out / name, (old, old))
    (out / "result.json").write_text(json.dumps({"cost": 1.0}))  # not a run
    (out / "deep.json").write_text("[" * 100_000 + "]" * 100_000)  # hostile: nor this
    return out


def test_the_folder_is_sorted_into_complete_and_incomplete_runs(folder):
    inv = inventory(folder)
    state = {r.run_id: (r.complete, r.problem, r.live) for r in inv.runs}
    assert state == {
        "a-good": (True, "", False),
        "b-timeout": (True, "", False),
        "c-killed": (False, "recording never finished (.partial), no summary", False),
        "d-nosummary": (False, "recording without its summary", False),
        "e-live": (False, "recording never finished (.partial), no summary", True)}
    assert sorted(p.name for p in inv.orphans) == ["c-killed.rrd.partial", "d-nosummary.rrd"]


def test_twin_runs_lists_status_and_figures(folder):
    proc = _twin("runs", str(folder), "--json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    rows = {r["run_id"]: r for r in doc["runs"]}
    good, cut = rows["a-good"], rows["b-timeout"]
    assert good["status"] == "FINISHED" and good["program"] == "builtin spline_line"
    assert good["machine"] == "tomsk_xy" and good["max_contour_error_um"] > 0
    summary = json.loads((folder / "a-good.json").read_text())
    assert good["cycle_time_s"] == summary["cycle_time_s"]
    assert cut["status"] == "TIMEOUT" and "max_time" in cut["reason"]
    assert doc["incomplete"] == 3 and doc["removed"] == []
    table = _twin("runs", str(folder))
    assert "recording without its summary" in table.stdout and "--clean" in table.stderr


def test_clean_asks_first_and_removes_only_the_leftovers(folder, tmp_path):
    work = tmp_path / "copy"
    work.mkdir()
    for p in folder.iterdir():
        (work / p.name).write_bytes(p.read_bytes())
        os.utime(work / p.name, (p.stat().st_atime, p.stat().st_mtime))
    refused = _twin("runs", str(work), "--clean")          # not a terminal: no silent yes
    assert refused.returncode == 1 and (work / "c-killed.rrd.partial").exists()
    proc = _twin("runs", str(work), "--clean", "--yes", "--json")
    assert proc.returncode == 0, proc.stderr
    removed = sorted(os.path.basename(p) for p in json.loads(proc.stdout)["removed"])
    assert removed == ["c-killed.rrd.partial", "d-nosummary.rrd"]
    left = sorted(p.name for p in work.iterdir())
    assert left == ["a-good.json", "a-good.rrd", "b-timeout.json", "b-timeout.rrd",
                    "deep.json", "e-live.rrd.partial", "result.json"]
    assert clean(inventory(work)) == []


def test_a_path_that_is_not_a_folder_is_refused(tmp_path):
    (tmp_path / "f").write_text("")
    proc = _twin("runs", str(tmp_path / "f"))
    assert proc.returncode == 2 and "is not a folder" in proc.stderr
