"""``twin tune`` as a user runs it: one JSON object on stdout, the files, located errors."""

import json
import os
import subprocess
import sys

import pytest

ENV = {**os.environ, "RERUN_ANALYTICS": "0"}


def _twin(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True,
                          text=True, env=ENV, cwd=cwd, timeout=300)


def test_cma_job_prints_one_json_object_and_writes_its_files(tmp_path):
    out = tmp_path / "job"
    r = _twin("tune", "--method", "cma", "--program", "tiny", "--budget-s", "300",
              "--max-runs", "8", "--workers", "1", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)                 # exactly one object
    assert r.stdout.strip().count("\n") == 0
    assert doc["method"] == "cma" and doc["runs"] == 8
    assert doc["best"]["cost"] <= doc["baseline"]["cost"]
    for key in ("overrides", "plot", "report", "result"):
        assert os.path.isfile(doc["files"][key])
    saved = json.loads((out / "result.json").read_text())
    assert len(saved["trials"]) == 8


def test_human_output_is_a_table(tmp_path):
    r = _twin("tune", "--method", "analytic", "--program", "tiny", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "max_coordinate_error" in r.stdout and "best.toml" in r.stdout


@pytest.mark.parametrize("args, message", [
    (("--method", "cma", "--program", "nope"), "Invalid value for '--program'"),
    (("--method", "ppo", "--policy", "missing.zip"), "policy: no such file"),
])
def test_errors_exit_2_naming_the_place(tmp_path, args, message):
    r = _twin("tune", *args, "--out", str(tmp_path), "--budget-s", "5")
    assert r.returncode == 2
    assert message in r.stderr and r.stdout == ""
