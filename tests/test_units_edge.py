"""Machine units at the edges: values with units at ``--set``, in override and machine TOML
files and in ``best.toml``; a bare number refused where the field is shown in another unit
than SI; help that gives each key's unit; messages in mm."""

import json
import os
import subprocess
import sys

import pytest

from tuning.report import read_overrides, write_overrides
from twin.config import load_machine
from twin.config.overrides import SHORT_KEYS, key_units, parse_sets, set_file_overrides
from twin.config.quantities import display_unit, to_si
from twin.config.schema import field_meta
from twin.errors import ConfigError

TWIN = [sys.executable, "-m", "twin.cli"]
ENV = {**os.environ, "RERUN_ANALYTICS": "0", "COLUMNS": "400"}


@pytest.mark.parametrize(("text", "unit", "si"), [
    ("900mm/min", "m/s", 0.015), ("900 mm/min", "m/s", 0.015), ("5um", "m", 5e-6),
    ("5 µm", "m", 5e-6), ("2 V/mm", "V/m", 2000.0), ("12ms", "s", 0.012),
    ("0.5 m/s²", "m/s²", 0.5), ("3 in/min", "m/s", 3 * 25.4e-3 / 60),
    ("1e3 N·m·s/rad", "N·m·s/rad", 1000.0), ("40 kg", "kg", 40.0), ("7", "1", 7.0),
])
def test_quantities_convert_to_the_fields_si_unit(text, unit, si):
    assert to_si(text, unit, "f") == pytest.approx(si, rel=1e-14)


@pytest.mark.parametrize(("text", "why"), [("12 kg", "is not in m/s"),
                                           ("fast", "is not a number with a unit"),
                                           ("inf mm/min", "must be finite"),
                                           ("((", "is not a number with a unit")])
def test_a_wrong_quantity_names_the_field(text, why):
    with pytest.raises(ConfigError, match=f"^controller.limits.max_velocity: .*{why}"):
        to_si(text, "m/s", "controller.limits.max_velocity")


def test_five_micrometres_are_exactly_five_micrometres():
    assert to_si("5um", "m", "f") == 5e-6       # not pint's 4.9999999999999996e-06


def test_set_takes_units_and_refuses_a_bare_number_where_the_display_is_not_si():
    cfg = load_machine("tomsk_xy").with_overrides(parse_sets([
        "max_velocity=900mm/min", "contour_tolerance=5um", "period=4ms", "kp=2 V/mm",
        "axes.*.transmission.backlash=3um", 'axes.x.mechanics.travel=["-1mm", "300mm"]']))
    assert cfg.controller.limits.max_velocity == pytest.approx(0.015, rel=1e-15)
    assert cfg.controller.contour_tolerance == 5e-6 and cfg.controller.period == 0.004
    assert cfg.controller.regulator.kp == 2000.0
    assert cfg.axes["x"].transmission.backlash == cfg.axes["y"].transmission.backlash == 3e-6
    assert cfg.axes["x"].mechanics.travel == (-0.001, 0.3)
    for item, unit in (("max_velocity=900", "mm/min"), ("contour_tolerance=5e-6", "µm"),
                       ("period=0.005", "ms"), ("rapid_velocity=900", "mm/min"),
                       ("axes.x.switches.limit_max=0.29", "mm")):
        with pytest.raises(ConfigError, match=f"give a unit: .*shown in {unit}"):
            parse_sets([item])
    # SI-shown fields keep their bare numbers (a gain, an acceleration, a mass)
    assert parse_sets(["kp=2000", "max_acceleration=0.3",
                       "axes.x.mechanics.carriage_mass=95"]) == {
        "controller.regulator.kp": 2000, "controller.limits.max_acceleration": 0.3,
        "axes.x.mechanics.carriage_mass": 95}


def test_every_short_key_states_its_unit():
    units = key_units()
    assert set(units) == set(SHORT_KEYS)
    for key, path in SHORT_KEYS.items():
        meta = field_meta(path)
        shown = display_unit(meta) if meta.get("unit") else None
        assert units[key] == (f"{shown}, with the unit" if shown else meta.get("unit") or "-")
    assert units["max_velocity"] == "mm/min, with the unit" and units["kp"] == "V/m"


def test_override_files_take_units_and_best_toml_carries_them(tmp_path):
    from envs.space import TuningSettings
    from twin.controller.gains import RegulatorGains

    settings = TuningSettings(RegulatorGains(kp=(2150.25, 1980.5), ki=(1e4, 2e4),
                                             dcu_alpha=((1.0, -2.5, 0.5), (0.25, 0.0, -1.0))),
                              4.2)
    best = write_overrides(tmp_path / "best.toml", settings.to_dict())
    text = best.read_text()
    assert 'kp = ["2150.25 V/m", "1980.5 V/m"]' in text and 'max_jerk = "4.2 m/s³"' in text
    back = read_overrides(best, settings.gains)
    assert back.gains.kp == (2150.25, 1980.5) and back.max_jerk == 4.2
    assert back.gains.dcu_alpha == settings.gains.dcu_alpha
    cfg = load_machine("tomsk_xy").with_overrides(set_file_overrides(best))
    assert cfg.controller.regulator.kp == (2150.25, 1980.5)
    assert cfg.controller.limits.max_jerk == 4.2
    # and a machine file may carry units too
    from twin.config.loader import MACHINES_DIR

    text = (MACHINES_DIR / "tomsk_xy.toml").read_text()
    text = text.replace("period = 5.0e-3", 'period = "4 ms"').replace(
        "max_velocity = 0.015 ", 'max_velocity = "600 mm/min" ')
    machine = tmp_path / "m.toml"
    machine.write_text(text)
    m = load_machine(str(machine))
    assert m.controller.period == 0.004 and m.controller.limits.max_velocity == 0.01


def _twin(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*TWIN, *args], capture_output=True, text=True, env=ENV, timeout=300)


def test_cli_refuses_a_bare_feed_with_one_line_naming_the_unit(tmp_path):
    done = _twin("run", "--builtin", "corner", "--set", "max_velocity=900", "--rerun", "none",
                 "--out", str(tmp_path))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.strip() == ("error: max_velocity: give a unit: max_velocity=900mm/min "
                                   "(this field is shown in mm/min; a bare 900 would be read "
                                   "in m/s)")


def test_cli_runs_with_a_feed_in_mm_per_min(tmp_path):
    done = _twin("run", "--builtin", "corner", "--set", "max_velocity=600mm/min", "--rerun",
                 "none", "--out", str(tmp_path), "--json")
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    saved = json.loads((tmp_path / f"{summary['run_id']}.json").read_text())
    assert saved["config"]["controller"]["limits"]["max_velocity"] == pytest.approx(0.01)


def test_help_gives_each_short_keys_unit():
    done = _twin("run", "--help")
    text = " ".join(done.stdout.replace("│", " ").split())
    assert "max_velocity (mm/min, with the unit)" in text and "kp (V/m)" in text


def test_jog_messages_are_in_millimetres(tmp_path):
    done = _twin("jog", "--axis", "x", "--distance", "1000", "--out", str(tmp_path))
    assert done.returncode == 2
    assert "leaves the work zone X 2 … 298 mm, Y 2 … 198 mm" in done.stderr
    done = _twin("home", "--from", "1000,1000", "--out", str(tmp_path))
    assert done.returncode == 2
    assert "(X 0 … 300 mm, Y 0 … 200 mm), got 1000, 1000 mm" in done.stderr
