"""Tuning jobs: the evaluator, CMA-ES, the files a job writes, and the acceptance figure
(black-box tuning beats the analytic DCU design by ≥ 20 % without more overshoot)."""

import math
import os
import re

import numpy as np
import pytest

from envs.evaluation import tuning_run
from tuning.cma_job import run_cma
from tuning.evaluator import Evaluator
from tuning.jobs import TuneSpec, tune
from tuning.report import read_overrides, write_overrides
from twin.config import load_machine
from twin.config.overrides import set_file_overrides
from twin.controller.controller import Controller
from twin.errors import ConfigError
from twin.session.run import axis_models

CI = os.environ.get("CI") == "true"


@pytest.fixture(scope="module")
def tiny():
    with Evaluator.create("tomsk_xy", "tiny") as ev:
        yield ev


def test_parallel_workers_give_the_same_trials(tiny):
    xs = [np.linspace(-0.3, 0.3, 11), np.full(11, -0.5), np.zeros(11)]
    with Evaluator(tiny.tuning, workers=2) as par:
        parallel = par.evaluate(xs)
    serial = Evaluator(tiny.tuning).evaluate(xs)
    for a, b in zip(parallel, serial, strict=True):
        assert a.cost == b.cost and a.metrics == b.metrics and a.x == b.x
    assert serial[2].cost == pytest.approx(tiny.baseline.cost, rel=1e-12)


def test_cma_improves_on_the_analytic_design_and_is_seeded(tiny):
    a = Evaluator(tiny.tuning)
    best = run_cma(a, budget_s=120.0, max_evals=24, seed=3)
    assert len(a.trials) == 24
    assert best.cost < tiny.baseline.cost
    assert best is min(a.trials, key=lambda t: t.cost)
    b = Evaluator(tiny.tuning)
    run_cma(b, budget_s=120.0, max_evals=12, seed=3)
    assert [t.x for t in b.trials] == [t.x for t in a.trials[:12]]


def test_cma_starts_a_generation_only_if_it_fits_in_the_budget(tiny):
    """Before the first generation, one is expected to last as long as the baseline run
    times the population (11 on one worker); a budget shorter than that runs none, a
    longer one runs it."""
    ev = Evaluator(tiny.tuning)
    generation = ev.baseline.wall_time * 11
    run_cma(ev, budget_s=0.5 * generation, seed=0)
    assert ev.trials == []
    run_cma(ev, budget_s=20.0 * generation, seed=0, max_evals=11)
    assert len(ev.trials) == 11


@pytest.mark.parametrize("bad, field", [({"budget_s": 0.0}, "budget_s"),
                                        ({"budget_s": 1.0, "sigma0": 2.0}, "sigma0")])
def test_cma_arguments(tiny, bad, field):
    with pytest.raises(ConfigError) as info:
        run_cma(Evaluator(tiny.tuning), **bad)
    assert info.value.field == field


def test_job_files_and_the_override_round_trip(tmp_path):
    result = tune(TuneSpec(method="cma", program="tiny", budget_s=60.0, max_runs=12,
                           workers=1, out_dir=tmp_path))
    for key in ("overrides", "plot", "report", "result", "runs"):
        assert result.files[key].is_file() and result.files[key].stat().st_size > 0
    for key in ("plot", "runs"):
        assert result.files[key].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| max_coordinate_error | µm |" in result.files["report"].read_text()
    # the TOML reproduces the best run exactly
    ev = Evaluator.create("tomsk_xy", "tiny")
    ev_space = ev.tuning
    # runs.png draws the very runs the report gives: the trace of the best settings peaks
    # at the best run's max coordinate error, the analytic one at the analytic run's
    for trial in (result.baseline, result.best):
        trace = ev.trace(trial.settings)
        assert np.abs(trace["error"]).max() == pytest.approx(
            trial.metrics["max_coordinate_error"], rel=1e-9)
        assert trace["t"][-1] == pytest.approx(trial.sim_time, abs=0.1)
    settings = read_overrides(result.files["overrides"], ev_space.space.analytic)
    assert settings.to_dict() == result.best.settings   # repr floats round-trip exactly
    again = tuning_run(ev_space.cfg, settings, models=ev_space.models, program="tiny")
    assert again.metrics == result.best.metrics
    flat = set_file_overrides(result.files["overrides"])
    assert set(flat) == {"controller.limits.max_jerk", "controller.regulator.kp",
                         "controller.regulator.ki", "controller.regulator.dcu_alpha"}
    # every value carries its unit, and reads back as the very float
    assert flat["controller.regulator.kp"] == [f"{v!r} V/m" for v in result.best.settings["kp"]]
    assert cfg_kp(ev_space.cfg.with_overrides(flat)) == tuple(result.best.settings["kp"])
    # ... and the machine accepts it: the controller runs with exactly the tuned settings
    cfg = ev_space.cfg.with_overrides(flat)
    ctrl = Controller.from_machine(cfg, None, axis_models=axis_models(cfg))
    np.testing.assert_array_equal(np.broadcast_to(ctrl.gains.kp, 2), settings.gains.kp)
    np.testing.assert_array_equal(np.broadcast_to(ctrl.gains.dcu_alpha, (2, 3)),
                                  np.broadcast_to(settings.gains.dcu_alpha, (2, 3)))
    assert cfg.controller.limits.max_jerk == settings.max_jerk


def cfg_kp(cfg):
    return cfg.controller.regulator.kp


def test_analytic_job_is_the_baseline(tmp_path):
    from tuning.report import rounded_settings

    result = tune(TuneSpec(method="analytic", program="tiny", out_dir=tmp_path))
    assert result.trials == [] and not result.improved
    # best.toml holds the analytic design rounded, and best is that file's run
    assert result.best.settings == rounded_settings(result.baseline.settings)
    assert result.best.cost == pytest.approx(result.baseline.cost, rel=0.01)
    assert abs(result.summary()["max_coordinate_error_reduction_pct"]) < 1.0
    assert "analytic design only" in result.summary()["notes"][0]
    text = result.files["overrides"].read_text()
    assert "analytic design only" in text
    numbers = [float(n) for n in re.findall(r'"(-?[0-9.e+-]+) ', text)]
    assert len(numbers) == 1 + 2 + 2 + 6                      # every value, at 5 digits
    for v in numbers:
        assert v == 0.0 or v == round(v, 4 - math.floor(math.log10(abs(v)))), v


def test_override_file_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[controller]\nx = 1\n")
    base = Evaluator.create("tomsk_xy", "tiny").tuning.space.analytic
    with pytest.raises(ConfigError, match="not a tuning override file"):
        read_overrides(bad, base)
    bad.write_text("[controller\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        read_overrides(bad, base)
    with pytest.raises(ConfigError, match="no such file"):
        set_file_overrides(tmp_path / "missing.toml")
    ok = write_overrides(tmp_path / "ok.toml", {"kp": [1.0, 2.0], "ki": [0.0, 0.0],
                                                "dcu_alpha": [[1, 2, 3], [4, 5, 6]],
                                                "max_jerk": 3.0})
    assert set_file_overrides(ok)["controller.regulator.dcu_alpha"] == [
        ["1.0 V/m", "2.0 V/m", "3.0 V/m"], ["4.0 V/m", "5.0 V/m", "6.0 V/m"]]
    cfg = load_machine("tomsk_xy").with_overrides(set_file_overrides(ok))
    assert cfg.controller.regulator.dcu_alpha == ((1.0, 2.0, 3.0), (4.0, 5.0, 6.0))
    assert cfg.controller.limits.max_jerk == 3.0


@pytest.mark.parametrize("bad, field", [({"method": "grid"}, "method"),
                                        ({"program": "nope"}, "program"),
                                        ({"budget_s": -1.0}, "budget_s"),
                                        ({"workers": 0}, "workers"),
                                        ({"weights": {"speed": 1.0}}, "weights.speed")])
def test_spec_validation(bad, field):
    with pytest.raises(ConfigError) as info:
        TuneSpec(**{"method": "cma", **bad})
    assert info.value.field == field


@pytest.mark.slow
def test_black_box_tuning_beats_the_analytic_dcu(tmp_path):
    """The acceptance figure. Full: the default program, 9 minutes, 2 workers. CI: the
    compact program (the default program shrunk to 5 %, same feeds and jerk phases) for
    120 runs (the search is seeded and the runs deterministic)."""
    spec = TuneSpec(method="cma", program="compact", budget_s=120.0, max_runs=120,
                    workers=2, out_dir=tmp_path) if CI else \
        TuneSpec(method="cma", program="default", budget_s=540.0, workers=2,
                 out_dir=tmp_path)
    result = tune(spec)
    base, best = result.baseline.metrics, result.best.metrics
    assert best["max_coordinate_error"] <= 0.8 * base["max_coordinate_error"]
    assert best["overshoot"] <= base["overshoot"]
    assert math.isfinite(result.best.cost) and result.best.cost < result.baseline.cost
    assert result.wall_time < 600.0


def test_tuned_shapers_round_trip_through_best_toml(tmp_path):
    """Random shaper settings written as best.toml read back bit for bit, and the file
    turns the machine's shapers on with them (type, frequency, damping)."""
    from envs.space import TuningSpace
    from tuning.report import rounded_settings

    cfg = load_machine("laser_belt").with_overrides(
        {f"controller.shaper.{a}.type": "mzv" for a in ("x", "y")})
    space = TuningSpace.from_machine(cfg, axis_models(cfg))
    rng = np.random.default_rng(7)
    for k in range(4):
        s = space.decode(rng.uniform(-1, 1, space.dim)).to_dict()
        path = write_overrides(tmp_path / f"b{k}.toml", s, shaper_type="mzv")
        back = read_overrides(path, space.analytic).to_dict()
        assert back == s
        loaded = cfg.with_overrides(set_file_overrides(path))
        for i, axis in enumerate(("x", "y")):
            got = getattr(loaded.controller.shaper, axis)
            assert (got.type, got.frequency, got.damping) == (
                "mzv", s["shaper_frequency"][i], s["shaper_damping"][i])
        assert set(rounded_settings(s)) == set(s)
