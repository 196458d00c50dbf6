"""The drive's settings as the machine's truth: the ``regulators`` section and the
low-current physics fields, their refusals, and ``design`` following the machine file."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from twin.config import load_machine, machine_from_toml_dict
from twin.config.writer import machine_to_toml
from twin.drive import design
from twin.errors import ConfigError

TOMSK = load_machine("tomsk_xy")
SETTINGS = ("current_kp", "current_ti", "speed_kp", "speed_ti")


def test_tomsk_xy_is_the_designed_digital_drive():
    for a in ("x", "y"):
        d = design(TOMSK.axes[a])
        assert d.implementation == "digital"
        assert d.regulator_overrides == ()
        assert d.current_regulator_designed
        assert d.current_filter == 0.0


@pytest.mark.parametrize("name", SETTINGS)
def test_an_override_replaces_that_one_value(name):
    rng = np.random.default_rng(sum(map(ord, name)))
    ax = TOMSK.axes["y"]
    derived = design(ax)
    for factor in rng.uniform(0.3, 3.0, 4):
        value = float(getattr(derived, name) * factor)
        d = design(TOMSK.with_overrides({f"axes.y.regulators.{name}": value}).axes["y"])
        assert getattr(d, name) == value
        assert d.regulator_overrides == (name,)
        for other in SETTINGS:
            if other != name:
                assert getattr(d, other) == getattr(derived, other)
        # nothing else of the design moves
        same = {f.name for f in dataclasses.fields(d)} - {name, "regulator_overrides"}
        assert all(getattr(d, f) == getattr(derived, f) for f in same)


def test_the_analog_design_lumps_the_filter_into_the_small_time_constant():
    rng = np.random.default_rng(7)
    for t_fi in rng.uniform(0.0, 3e-3, 5):
        ax = TOMSK.with_overrides({"axes.y.regulators.implementation": "analog",
                                   "axes.y.regulators.current_filter": float(t_fi)}).axes["y"]
        d = design(ax)
        t_p = ax.converter.firing_period
        assert d.converter_time_constant == pytest.approx(0.5 * t_p + t_fi, rel=1e-14)
        assert d.current_kp == pytest.approx(d.inductance / (2 * (0.5 * t_p + t_fi)))
        assert d.small_time_constant == pytest.approx(
            2 * (0.5 * t_p + t_fi) + ax.tacho.filter_time_constant)


def test_the_circuit_the_current_loop_is_designed_on():
    ax = TOMSK.with_overrides({"axes.y.converter.thyristor_resistance": 0.05,
                               "axes.y.converter.smoothing_inductance": 0.02,
                               "axes.y.converter.line_inductance": 1e-4}).axes["y"]
    d = design(ax)
    assert d.resistance == pytest.approx(2.0 + 2 * 0.05)
    assert d.inductance == pytest.approx(10e-3 + 0.02 + 2 * 1e-4)
    assert d.armature_time_constant == pytest.approx(d.inductance / d.resistance)


@pytest.mark.parametrize(("override", "field"), [
    ({"axes.x.motor.brush_drop": -0.5}, "axes.x.motor.brush_drop"),
    ({"axes.y.converter.thyristor_threshold": -0.1}, "axes.y.converter.thyristor_threshold"),
    ({"axes.y.converter.thyristor_resistance": -0.01},
     "axes.y.converter.thyristor_resistance"),
    ({"axes.x.converter.smoothing_inductance": -1e-3},
     "axes.x.converter.smoothing_inductance"),
    ({"axes.x.converter.latching_current": 0.05, "axes.x.converter.holding_current": 0.1},
     "axes.x.converter.holding_current"),
    ({"axes.x.converter.holding_current": 0.1}, "axes.x.converter.holding_current"),
    ({"axes.x.converter.min_firing_angle": math.radians(150.0)},
     "axes.x.converter.min_firing_angle"),
    ({"axes.x.converter.min_firing_angle": math.radians(30.0),
      "axes.x.converter.max_firing_angle": math.radians(20.0)},
     "axes.x.converter.min_firing_angle"),
    ({"axes.x.converter.mains_deviation": 0.5}, "axes.x.converter.mains_deviation"),
    ({"axes.x.converter.gate_pulse_width": -1e-4}, "axes.x.converter.gate_pulse_width"),
    ({"axes.x.regulators.current_kp": 0.0}, "axes.x.regulators.current_kp"),
    ({"axes.x.regulators.speed_ti": -1.0}, "axes.x.regulators.speed_ti"),
    ({"axes.x.regulators.implementation": "hydraulic"}, "axes.x.regulators.implementation"),
    ({"axes.x.regulators.current_filter": -1e-3}, "axes.x.regulators.current_filter"),
    ({"axes.x.converter.model": "mean", "axes.x.regulators.implementation": "analog"},
     "axes.x.regulators.implementation"),
    ({"axes.x.converter.model": "mean", "axes.x.converter.latching_current": 0.1},
     "axes.x.converter.latching_current"),
])
def test_bad_drive_values_name_the_field(override, field):
    with pytest.raises(ConfigError) as err:
        TOMSK.with_overrides(override)
    assert err.value.field == field


def test_brush_drop_on_a_pwm_drive_is_refused():
    laser = load_machine("laser_belt")
    with pytest.raises(ConfigError) as err:
        laser.with_overrides({"axes.x.motor.brush_drop": 1.0})
    assert err.value.field == "axes.x.motor.brush_drop"


def test_the_settings_survive_a_machine_file():
    import tomllib

    cfg = TOMSK.with_overrides({"axes.x.regulators.speed_kp": 1.5,
                                "axes.x.regulators.implementation": "analog",
                                "axes.y.regulators.current_ti": 4e-3,
                                "axes.*.motor.brush_drop": 1.5,
                                "axes.*.converter.latching_current": 0.2,
                                "axes.*.converter.holding_current": 0.05})
    again = machine_from_toml_dict(tomllib.loads(machine_to_toml(cfg)))
    for a in ("x", "y"):
        assert again.axes[a] == cfg.axes[a]
        assert design(again.axes[a]) == design(cfg.axes[a])


def test_machines_fields_lists_each_setting_with_unit_and_range():
    from typer.testing import CliRunner

    from twin.cli.main import app

    result = CliRunner().invoke(app, ["machines", "--fields", "tomsk_xy", "--json"])
    assert result.exit_code == 0, result.output
    rows = {r["field"]: r for r in json.loads(result.stdout)["fields"]}
    expect = {"motor.brush_drop": "V", "converter.thyristor_threshold": "V",
              "converter.thyristor_resistance": "Ω", "converter.latching_current": "A",
              "converter.holding_current": "A", "converter.gate_pulse_width": "s",
              "converter.smoothing_inductance": "H", "converter.mains_deviation": "1",
              "converter.min_firing_angle": "rad", "converter.max_firing_angle": "rad",
              "regulators.current_kp": "V/A", "regulators.current_ti": "s",
              "regulators.speed_kp": "A/V", "regulators.speed_ti": "s",
              "regulators.current_filter": "s"}
    for a in ("x", "y"):
        for name, unit in expect.items():
            row = rows[f"axes.{a}.{name}"]
            assert row["unit"] == unit and row["range"].startswith(("[", "(")), row
            assert row["meaning"]
        assert rows[f"axes.{a}.regulators.implementation"]["range"] == \
            "one of digital, analog"


def test_the_analog_current_filter_closed_form_matches_solve_ivp():
    """filter_current: T_f·y' = j(t) − y for the bridge's piece current, against DOP853 over
    random pieces (τ near T_f included)."""
    from scipy.integrate import solve_ivp

    from twin.drive.analog import filter_current

    rng = np.random.default_rng(11)
    w = 2 * math.pi * 50.0
    for _ in range(30):
        j0, pc, ps, a, b = rng.normal(0.0, 2.0, 5)
        tau = float(rng.uniform(1e-3, 0.05))
        tf = float(rng.choice([rng.uniform(1e-4, 5e-3), tau * (1 + 1e-5)]))
        y0, t = float(rng.normal()), float(rng.uniform(1e-4, 3e-3))

        def j(s, j0=j0, pc=pc, ps=ps, a=a, b=b, tau=tau):
            return (pc * np.cos(w * s) + ps * np.sin(w * s) + a + b * s
                    + (j0 - pc - a) * np.exp(-s / tau))
        sol = solve_ivp(lambda s, y, tf=tf, j=j: [(j(s) - y[0]) / tf], (0.0, t), [y0],
                        method="DOP853", rtol=1e-12, atol=1e-14)
        got = filter_current(y0, t, j0, pc, ps, a, b, tau, w, tf)
        assert got == pytest.approx(sol.y[0, -1], rel=1e-8, abs=1e-10)
