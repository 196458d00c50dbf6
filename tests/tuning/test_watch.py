"""Tuning you can watch: a folder per job, progress lines outside a terminal, the cost
weights said and saved, physical values in Optuna, a convergence plot for every method."""

import json
import os
import subprocess
import sys
from pathlib import Path

import optuna
import pytest

from tuning.jobs import TuneSpec, job_folder, tune
from tuning.optuna_job import physical_values
from twin.errors import ConfigError

ENV = {**os.environ, "RERUN_ANALYTICS": "0"}


def test_a_job_gets_a_folder_of_its_own_and_resume_takes_the_newest_of_its_kind(tmp_path):
    spec = TuneSpec(method="cma", program="tiny", machine="tomsk_xy")
    first = job_folder(spec, tmp_path)
    assert first.parent == tmp_path and first.name.startswith("tomsk_xy-tiny-cma-")
    with pytest.raises(ConfigError, match="no earlier cma job of tomsk_xy on tiny"):
        job_folder(TuneSpec(method="cma", program="tiny", resume=True), tmp_path)
    for name in ("tomsk_xy-tiny-cma-20260101-000000", "tomsk_xy-tiny-cma-20260102-000000",
                 "laser_belt-tiny-cma-20270101-000000", "tomsk_xy-tiny-ppo-20270101-000000"):
        (tmp_path / name).mkdir()
    resumed = job_folder(TuneSpec(method="cma", program="tiny", resume=True), tmp_path)
    assert resumed.name == "tomsk_xy-tiny-cma-20260102-000000"   # never another machine's
    machine_file = TuneSpec(method="ppo", program="tiny", machine="/x/my_mill.toml")
    assert job_folder(machine_file, tmp_path).name.startswith("my_mill-tiny-ppo-")


def test_outside_a_terminal_a_job_says_its_folder_weights_and_progress(tmp_path):
    out = tmp_path / "job"
    done = subprocess.run([sys.executable, "-m", "twin.cli", "tune", "--method", "cma",
                           "--program", "tiny", "--workers", "1", "--max-runs", "6",
                           "--budget-s", "120", "--out", str(out), "--json"],
                          capture_output=True, text=True, env=ENV, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stderr.strip().splitlines()
    assert lines[0].startswith(f"cma: job folder {out}; cost = 1·max_coordinate_error + ")
    progress = [ln for ln in lines[1:] if ln.startswith("cma: ")]
    assert progress and progress[-1].startswith("cma: 6 runs, best cost ")
    assert progress[-1].endswith(" s of 120 s")
    summary = json.loads(done.stdout)
    weights = json.loads((out / "result.json").read_text())["weights"]
    assert summary["weights"] == weights and weights["max_coordinate_error"] == 1.0
    assert "## Cost weights" in (out / "report.md").read_text()


def test_optuna_trials_carry_the_gains_in_their_units(tmp_path):
    result = tune(TuneSpec(method="optuna", program="tiny", workers=1, max_runs=3,
                           budget_s=120.0, out_dir=tmp_path))
    study = optuna.load_study(study_name="tomsk_xy-tiny",
                              storage=f"sqlite:///{tmp_path / 'optuna.db'}")
    done = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(done) == 4                                  # the baseline and three runs
    for t in done:
        attrs = t.user_attrs
        s = attrs["settings"]
        assert attrs["kp_x [V/m]"] == s["kp"][0] and attrs["ki_y [V/(m·s)]"] == s["ki"][1]
        assert attrs["dcu_alpha3_y [V/m]"] == s["dcu_alpha"][1][2]
        assert attrs["max_jerk [m/s³]"] == s["max_jerk"]
    assert len(physical_values(result.best.settings)) == 2 * (2 + 3) + 1


def test_the_analytic_job_plots_its_one_point(tmp_path):
    import matplotlib.image

    result = tune(TuneSpec(method="analytic", program="tiny", out_dir=tmp_path))
    png = matplotlib.image.imread(result.files["plot"])
    # the run-0 marker of the analytic design is drawn in C3 red (214, 39, 40)
    red = (abs(png[..., 0] - 214 / 255) < 0.05) & (abs(png[..., 1] - 39 / 255) < 0.05) \
        & (abs(png[..., 2] - 40 / 255) < 0.05)
    assert red.sum() > 50
    assert Path(result.files["plot"]).stat().st_size > 5000
