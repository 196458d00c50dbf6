"""Issue 2, test 2: the elastic modes of the MuJoCo model against the analytic lumped model.

The analytic numbers come from ``twin.plant.model.axis_mechanics``, the function that
``models/README.md`` tabulates; the measurement is the spectral peak of the axial spring
deflection's second derivative after a step at mid-travel (see ``tests/plant/modal.py``).
The free vibration at three nut positions, within 1 %, is in ``test_chain.py``.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from tests.plant.modal import mid_travel, peak_frequency, step_response_rate
from twin.config import load_machine
from twin.plant import Plant
from twin.plant.model import MODELS_DIR, axis_mechanics

CASES = [(machine, axis) for machine in ("tomsk_xy", "laser_belt") for axis in ("x", "y")]
TOLERANCE = 0.05  # the bound; the measured error is below 1 % (README)
RECORD = 0.3  # s: ≥ 10 decay time constants of every mode of both presets


def _torque_step(cfg, axis: str) -> float:
    """A rotor torque (N·m) that moves the table a quarter of its travel in the record, so
    it keeps moving one way (constant Coulomb friction) and stays clear of the end stops."""
    mech, r = cfg.axes[axis].mechanics, cfg.axes[axis].transmission.ratio
    am = axis_mechanics(cfg, axis)
    quarter = (mech.travel[1] - mech.travel[0]) / 4.0
    acceleration = 2.0 * quarter / RECORD**2
    return acceleration / r * (am.rotor_inertia + (am.moving_mass + am.screw_mass) * r**2)


def _mid(cfg, axis: str) -> float:
    return float(mid_travel(cfg)["xy".index(axis)])


@pytest.mark.parametrize(("machine", "axis"), CASES)
def test_free_rotor_mode_from_torque_step(machine, axis):
    cfg = load_machine(machine)
    am = axis_mechanics(cfg, axis, _mid(cfg, axis))
    rate, dt = step_response_rate(cfg, axis, rotor_torque=_torque_step(cfg, axis),
                                  duration=RECORD)
    expected = am.free_rotor_frequency
    measured = peak_frequency(rate, dt, (0.5 * expected, 2.0 * expected))
    assert measured == pytest.approx(expected, rel=TOLERANCE)


@pytest.mark.parametrize(("machine", "axis"), CASES)
def test_locked_rotor_mode_from_table_force_step(machine, axis):
    # The rotor is "locked" by the largest inertia the schema allows (10 kg·m²: 10⁴-fold
    # or more); the slide's Coulomb friction is off because a table oscillating about a
    # fixed point would stick and slip on it.
    cfg = load_machine(machine)
    locked = cfg.with_overrides({
        f"axes.{axis}.mechanics.rotor_inertia": 10.0,
        f"axes.{axis}.mechanics.slide_coulomb": 0.0,
    })
    am = axis_mechanics(cfg, axis, _mid(cfg, axis))
    rate, dt = step_response_rate(locked, axis, table_force=50.0, duration=RECORD)
    expected = am.locked_rotor_frequency
    measured = peak_frequency(rate, dt, (0.5 * expected, 2.0 * expected))
    assert measured == pytest.approx(expected, rel=TOLERANCE)
    if am.has_screw:  # a free rotor can only raise the first mode
        assert am.free_rotor_frequency > expected
    else:  # two masses: it differs from the free-rotor one by the mass ratio only
        assert am.free_rotor_frequency == pytest.approx(
            expected * np.sqrt(1.0 + am.mass_ratio), rel=1e-12)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_reference_step_through_the_drive_excites_the_same_mode(axis):
    # tomsk_xy: the reflected rotor inertia (158 t) dwarfs the table, so the speed loop cannot
    # move the mode; a 1 V reference step through the thyristor drive must show it too.
    # (laser_belt's mode lies between its locked- and free-rotor values and depends on the
    # speed loop: README, "The modes under the speed loop".)
    plant = Plant.from_machine("tomsk_xy")
    plant.reset(positions=mid_travel(plant.config))
    screw = plant.model.tendon(f"{axis}_screw").id
    rate = [0.0]
    for _ in range(round(RECORD / plant.drive_dt)):
        plant.step(np.array([1.0, 1.0]), plant.drive_dt)
        rate.append(float(plant.data.ten_velocity[screw]))
    am = axis_mechanics(plant.config, axis, _mid(plant.config, axis))
    expected = am.locked_rotor_frequency
    measured = peak_frequency(np.array(rate), plant.drive_dt, (0.5 * expected, 1.5 * expected))
    assert measured == pytest.approx(expected, rel=TOLERANCE)


def _number(cell: str) -> float:
    return math.inf if cell == "∞" else float(cell.replace(" ", ""))


def _readme_rows() -> dict[tuple[str, str], list[float]]:
    """Rows of the README's mode table at the reference position:
    | machine | axis | m | k | m_s | k_g | M | ω_L | ω_F | ζ_F | c |."""
    text = (MODELS_DIR / "README.md").read_text(encoding="utf-8")
    rows = {}
    for line in text.splitlines():
        match = re.match(r"\|\s*`(\w+)`\s*\|\s*([xy])\s*\|((?:[^|]*\|){9})\s*$", line)
        if match:
            cells = [c.strip() for c in match.group(3).split("|")[:9]]
            rows[(match.group(1), match.group(2))] = [_number(c) for c in cells]
    return rows


@pytest.mark.parametrize(("machine", "axis"), CASES)
def test_readme_mode_table_matches_the_analytic_model(machine, axis):
    rows = _readme_rows()
    assert (machine, axis) in rows, f"models/README.md has no mode row for {machine} {axis}"
    am = axis_mechanics(load_machine(machine), axis)
    expected = [am.moving_mass, am.stiffness, am.screw_mass, am.gear_stiffness,
                am.reflected_mass, am.locked_rotor_frequency, am.free_rotor_frequency,
                am.free_rotor_damping_ratio, am.damping]
    assert rows[(machine, axis)] == pytest.approx(expected, rel=5e-3)


def _readme_positions() -> list[tuple[str, float, list[float]]]:
    """Rows of the README's table along the travel of tomsk_xy:
    | axis | position (mm) | k | ω_F | ω_2 | ζ_F | simulated error |."""
    text = (MODELS_DIR / "README.md").read_text(encoding="utf-8")
    rows = []
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 7 and cells[0] in ("x", "y") and cells[6].endswith("%"):
            rows.append((cells[0], float(cells[1]) * 1e-3, [_number(c) for c in cells[2:6]]))
    return rows


def test_readme_table_along_the_travel_matches_the_analytic_model():
    rows = _readme_positions()
    assert len(rows) == 6, "models/README.md: three positions per axis of tomsk_xy"
    cfg = load_machine("tomsk_xy")
    for axis, position, numbers in rows:
        am = axis_mechanics(cfg, axis, position)
        modes = am.frequencies("free")
        assert numbers == pytest.approx([am.stiffness, modes[0], modes[1],
                                         am.free_rotor_damping_ratio], rel=5e-3)
