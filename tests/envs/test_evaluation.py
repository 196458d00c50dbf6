"""One tuning run and its cost: the metrics against the controller's own record, the
terms against their definition, failures as flagged outcomes."""

import dataclasses
import math

import numpy as np
import pytest

from envs.evaluation import (
    METRICS,
    RunOutcome,
    Weights,
    cost_terms,
    metric_scales,
    tuning_run,
)
from envs.space import TuningSettings, TuningSpace
from twin.config import load_machine
from twin.errors import ConfigError, SimulationError
from twin.plant import Plant
from twin.session.run import RunSpec, axis_models, prepare, run_summary


@pytest.fixture(scope="module")
def tomsk():
    cfg = load_machine("tomsk_xy")
    models = axis_models(cfg)
    return cfg, models, TuningSpace.from_machine(cfg, models)


def test_baseline_metrics_match_twin_run(tomsk, tmp_path):
    """The analytic design on the default program is what ``twin run --dcu-order 3`` measures
    (the same controller and plant, another code path)."""
    cfg, models, space = tomsk
    spec = RunSpec(machine="tomsk_xy", dcu_order=3, builtin="spline_line")
    p = prepare(spec)
    ctrl = p.controller
    while not ctrl.done:
        p.driver.write(ctrl.tick(p.driver.read()))
    rec = ctrl.record.as_arrays()
    rec["table_velocity"] = np.gradient(rec["position"], rec["t"], axis=0)
    ref = run_summary(rec, p.path)
    out = tuning_run(cfg, space.decode(np.zeros(11)), models=models, program="spline_line")
    assert out.status == "FINISHED" and not out.failed
    assert out.metrics["max_coordinate_error"] * 1e6 == pytest.approx(
        max(ref["max_coordinate_error_um"].values()), rel=1e-12)
    assert out.metrics["max_contour_error"] * 1e6 == pytest.approx(
        ref["max_contour_error_um"], rel=1e-12)
    assert out.metrics["cycle_time"] == pytest.approx(ref["cycle_time_s"], rel=1e-12)
    assert out.metrics["overshoot"] * 1e6 == pytest.approx(ref["overshoot_um"], abs=1e-9)


def test_runs_are_deterministic(tomsk):
    cfg, models, space = tomsk
    a = np.linspace(-0.5, 0.5, 11)
    one = tuning_run(cfg, space.decode(a), models=models, program="tiny")
    two = tuning_run(cfg, space.decode(a), models=models, program="tiny")
    assert one.metrics == two.metrics


def test_saturation_time_counts_clipped_ticks(tomsk):
    cfg, models, space = tomsk
    base = space.decode(np.zeros(11))
    tight = dataclasses.replace(base.gains, output_limit=0.9, dac_bits=None)
    out = tuning_run(cfg, TuningSettings(tight, base.max_jerk), models=models,
                     program="tiny", max_time=30.0)
    assert not out.failed
    assert out.metrics["saturation_time"] > 0.0
    calm = tuning_run(cfg, base, models=models, program="tiny")
    assert calm.metrics["saturation_time"] == 0.0


def test_trip_is_a_failed_outcome(tomsk):
    cfg, models, space = tomsk
    base = space.decode(np.zeros(11))
    g = dataclasses.replace(base.gains, following_error_limit=1e-7, dcu_alpha=(0, 0, 0))
    out = tuning_run(cfg, TuningSettings(g, base.max_jerk), models=models, program="tiny")
    assert out.tripped and not out.diverged and out.status == "FOLLOWING_ERROR"
    assert all(math.isnan(v) for v in out.metrics.values())


def test_divergence_is_a_failed_outcome(tomsk, monkeypatch):
    cfg, models, space = tomsk
    calls = {"n": 0}
    step = Plant.step

    def exploding(self, volts, duration):
        calls["n"] += 1
        if calls["n"] > 20:
            raise SimulationError("the plant state diverged (not finite)")
        return step(self, volts, duration)

    monkeypatch.setattr(Plant, "step", exploding)
    out = tuning_run(cfg, space.decode(np.zeros(11)), models=models, program="tiny")
    assert out.diverged and out.status == "DIVERGED" and "diverged" in out.message
    assert out.sim_time == pytest.approx(20 * cfg.controller.period)


def _outcome(**metrics):
    values = dict.fromkeys(METRICS, 2e-6)
    values.update(cycle_time=2.0, saturation_time=0.0)
    values.update(metrics)
    return RunOutcome(values, "FINISHED")


def test_cost_terms_are_weighted_ratios():
    base = _outcome(overshoot=0.0)
    scales = metric_scales(base)
    assert scales["overshoot"] == 1e-6                  # floored
    assert scales["saturation_time"] == pytest.approx(0.02)  # 1 % of the cycle time
    w = Weights(max_coordinate_error=2.0, overshoot=3.0)
    run = _outcome(max_coordinate_error=1e-6, overshoot=4e-6, saturation_time=0.01)
    terms = cost_terms(run, scales, w, penalty=50.0)
    assert terms["max_coordinate_error"] == pytest.approx(2.0 * 0.5)
    assert terms["overshoot"] == pytest.approx(3.0 * 4.0)
    assert terms["saturation_time"] == pytest.approx(w.saturation_time * 0.5)
    assert terms["failure"] == 0.0
    base_terms = cost_terms(base, scales, Weights(), penalty=50.0)
    for m in METRICS:
        expected = 0.0 if m in ("overshoot", "saturation_time") else getattr(Weights(), m)
        assert base_terms[m] == pytest.approx(expected)


def test_failed_run_costs_the_penalty():
    bad = RunOutcome(dict.fromkeys(METRICS, math.nan), "DIVERGED", diverged=True)
    terms = cost_terms(bad, metric_scales(_outcome()), Weights(), penalty=7.0)
    assert terms == {**dict.fromkeys(METRICS, 0.0), "failure": 7.0}
    with pytest.raises(ValueError, match="baseline run failed"):
        metric_scales(bad)


@pytest.mark.parametrize("values, field", [
    ({"overshoot": -1.0}, "weights.overshoot"),
    ({"cycle_time": math.nan}, "weights.cycle_time"),
    ({"speed": 1.0}, "weights.speed"),
])
def test_weights_validation(values, field):
    with pytest.raises(ConfigError) as info:
        Weights.from_mapping(values)
    assert info.value.field == field
