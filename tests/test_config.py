"""Machine files load, validate, and name the field on every error."""

import math

import pytest

from twin.config import available_machines, load_machine, machine_from_toml_dict
from twin.errors import ConfigError


@pytest.mark.parametrize("name", ["tomsk_xy", "laser_belt"])
def test_presets_load(name):
    cfg = load_machine(name)
    assert cfg.name == name
    assert set(cfg.axes) == {"x", "y"}
    assert name in available_machines()


def test_tomsk_encoder_gives_five_counts_per_micrometre():
    ax = load_machine("tomsk_xy").axes["x"]
    # 2500 counts/rev, i = 12, 6 mm lead: 0.5 mm per motor revolution.
    assert ax.transmission.ratio == pytest.approx(6e-3 / (2 * math.pi * 12))
    assert ax.counts_per_metre == pytest.approx(5e6)


def test_series_stiffness():
    tr = load_machine("tomsk_xy").axes["x"].transmission
    assert tr.axial_stiffness == pytest.approx(1 / sum(1 / k for k in tr.stiffness.values()))
    assert tr.axial_stiffness < min(tr.stiffness.values())


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ({"axes.x.mechanics.carriage_mass": -1.0}, "axes.x.mechanics.carriage_mass"),
        ({"axes.y.motor.armature_resistance": 0.0}, "axes.y.motor.armature_resistance"),
        ({"controller.period": float("nan")}, "controller.period"),
        ({"axes.x.motor.emf_constant": "fast"}, "axes.x.motor.emf_constant"),
        ({"controller.regulator.kpp": 1.0}, "controller.regulator.kpp"),
        # the non-idealities of issue 10
        ({"axes.x.transmission.backlash": -1e-6}, "axes.x.transmission.backlash"),
        ({"axes.y.tacho.ripple": [[1, 100.0]]}, "axes.y.tacho.ripple[0]"),
        ({"axes.y.tacho.ripple": [[0, 1.0]]}, "axes.y.tacho.ripple[0]"),
        ({"axes.x.tacho.ripple": [[1, 1.0]] * 5}, "axes.x.tacho.ripple"),
        ({"axes.x.tacho.noise": -0.1}, "axes.x.tacho.noise"),
        ({"axes.x.mechanics.slide_breakaway": 10.0}, "axes.x.mechanics.slide_breakaway"),
        ({"axes.x.mechanics.stribeck_velocity": 0.0}, "axes.x.mechanics.stribeck_velocity"),
        ({"axes.x.dac.gain_error": 0.9}, "axes.x.dac.gain_error"),
        ({"axes.x.dac.offset": 5.0}, "axes.x.dac.offset"),
        ({"axes.x.converter.pulse_number": 12}, "axes.x.converter.pulse_number"),
        ({"axes.x.converter.model": "exact"}, "axes.x.converter.model"),
        ({"axes.x.converter.line_inductance": -1e-3}, "axes.x.converter.line_inductance"),
        ({"controller.timing.late_probability": 1.5}, "controller.timing.late_probability"),
        ({"controller.timing.skip_probability": -0.5}, "controller.timing.skip_probability"),
        ({"controller.timing.late_probability": 0.6,
          "controller.timing.skip_probability": 0.6}, "controller.timing.skip_probability"),
        ({"controller.in_position_tolerance": 0.0}, "controller.in_position_tolerance"),
    ],
)
def test_bad_values_name_the_field(override, field):
    cfg = load_machine("tomsk_xy")
    with pytest.raises(ConfigError) as exc:
        cfg.with_overrides(override)
    assert exc.value.field == field


def test_unknown_key_lists_valid_ones():
    with pytest.raises(ConfigError, match=r"valid here: .*kp"):
        load_machine("tomsk_xy").with_overrides({"controller.regulator.gain": 1.0})


@pytest.mark.parametrize("table", ["machine", "axis_defaults.mechanics", "axes.y.converter",
                                   "controller", "controller.regulator", "simulation"])
def test_an_unknown_key_in_any_table_of_a_machine_file_is_refused(table):
    import tomllib

    from twin.config.loader import MACHINES_DIR

    doc = tomllib.loads((MACHINES_DIR / "tomsk_xy.toml").read_text())
    node = doc
    for part in table.split("."):
        node = node.setdefault(part, {})
    node["speling_mistake"] = 1.0
    with pytest.raises(ConfigError) as exc:
        machine_from_toml_dict(doc)
    assert exc.value.field.endswith("speling_mistake") and "unknown key" in str(exc.value)


def test_missing_parameter_is_named():
    doc = {"machine": {"name": "m"}, "axis_defaults": {}, "controller": {}}
    with pytest.raises(ConfigError, match=r"axes\.x\.mechanics: missing"):
        machine_from_toml_dict(doc)


def test_wildcard_override_sets_both_axes():
    cfg = load_machine("tomsk_xy").with_overrides({"axes.*.mechanics.slide_coulomb": 7.0})
    assert cfg.axes["x"].mechanics.slide_coulomb == 7.0
    assert cfg.axes["y"].mechanics.slide_coulomb == 7.0


def test_unknown_preset():
    with pytest.raises(ConfigError, match=r"presets: .*tomsk_xy"):
        load_machine("no_such_machine")


def test_a_period_that_is_not_whole_drive_intervals_is_refused_naming_it():
    # laser_belt's 3.5 ms period is 14 of its 0.25 ms timesteps; with the schema's default
    # timestep (0.2 ms) it is 17.5 drive intervals, which the twin cannot step
    import tomllib

    from twin.config.loader import MACHINES_DIR

    doc = tomllib.loads((MACHINES_DIR / "laser_belt.toml").read_text())
    del doc["simulation"]["timestep"]
    with pytest.raises(ConfigError) as exc:
        machine_from_toml_dict(doc)
    assert exc.value.field == "controller.period" and "0.0002 s × 1" in exc.value.message
    with pytest.raises(ConfigError, match="whole number of the twin's drive intervals"):
        load_machine("tomsk_xy").with_overrides({"controller.period": 3.3e-3})
    assert load_machine("tomsk_xy").with_overrides({"controller.period": 3e-3})


def test_the_schema_choices_are_the_controllers():
    from twin.config.schema import PLANNERS, PROFILES
    from twin.controller.planner import MODES
    from twin.controller.profiles.laws import LAWS

    assert PROFILES == LAWS and PLANNERS == MODES


@pytest.mark.parametrize("machine", ["tomsk_xy", "laser_belt"])
def test_every_field_states_its_range_and_meaning(machine):
    """``twin machines --fields``: each field with its value, range (or choices) and
    meaning; every number lies inside its range."""
    import json

    from typer.testing import CliRunner

    from twin.cli import app

    result = CliRunner().invoke(app, ["machines", "--fields", machine, "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)["fields"]
    assert len(rows) > 100
    for row in rows:
        if row["field"] in ("name", "description"):
            continue
        assert row["meaning"], row["field"]
        # a table of pairs states its range in its meaning (checked by its own _check); a
        # list of folders has none
        assert row["range"] or row["field"].endswith((".ripple", ".work_offsets",
                                                      ".subroutine_path", ".owners")), \
            row["field"]
        values = row["value"] if isinstance(row["value"], list) else [row["value"]]
        for v in values:
            if isinstance(v, bool) or not isinstance(v, int | float):
                continue
            lo, hi = row["range"].split(" ")[0:2]
            low, high = float(lo[1:-1]), float(hi.rstrip("]").rstrip(")"))
            assert (low < v if lo[0] == "(" else low <= v) and v <= high, row
