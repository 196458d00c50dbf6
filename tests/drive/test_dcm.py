"""Discontinuous conduction at feed speed, on the whole twin (MuJoCo table, both drives):
seed 000's Table 2 feed, 0.44 mm/s, is deep in discontinuous conduction; the adapted
current regulator holds it, the plain one limit-cycles, and so does a mistuned analog drive
without adaptation (docs/examples/tomsk_xy_as_built.toml)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.config import load_machine
from twin.drive.dcm import boundary_current
from twin.plant import FINE_FIELDS, Plant

FEED = 0.44e-3  # m/s, seed 000 Table 2


def _column(name: str, axis: int) -> int:
    col = 0
    for field, width in FINE_FIELDS:
        if field == name:
            return col + axis
        col += width
    raise KeyError(name)


AS_BUILT = Path(__file__).resolve().parents[2] / "docs" / "examples" / "tomsk_xy_as_built.toml"


def _hold_feed(compensation: bool, seconds: float = 2.0, machine: str = "tomsk_xy"):
    """Both axes' DAC at the reference for FEED; drive-rate samples of the last second."""
    cfg = load_machine(machine).with_overrides(
        {"axes.*.converter.dcm_compensation": compensation})
    plant = Plant(cfg)
    plant.reset()
    ax = cfg.axes["x"]
    u = FEED * ax.volts_per_speed
    rows = []
    for _ in range(round(seconds / cfg.controller.period)):
        plant.step(np.array([u, u]), cfg.controller.period)
        rows.append(plant.fine.copy())
    fine = np.concatenate(rows)
    return cfg, plant, fine[len(fine) // 2:]


def _speed(plant, fine, axis):
    x = fine[:, _column("table_position", axis)]
    return np.gradient(x, plant.drive_dt)


def test_table_2_feed_is_deep_in_discontinuous_conduction():
    cfg, plant, fine = _hold_feed(True)
    ax = cfg.axes["x"]
    current = fine[:, _column("armature_current", 0)]
    conduction = fine[:, _column("conduction", 0)]
    assert current.min() == 0.0 and current.max() > 0.0
    assert conduction.mean() < 0.5  # current flows less than half the time
    mean_current = float(plant.drives.measured_current[0])
    a = (2 * np.pi * ax.converter.mains_frequency * ax.motor.armature_inductance
         / ax.motor.armature_resistance)
    i_b90 = boundary_current(np.pi / 2, 6, a) * ax.converter.peak_voltage \
        / ax.motor.armature_resistance
    assert 0.0 < mean_current < 0.05 * i_b90  # a few percent of the boundary current


def test_the_adapted_current_regulator_holds_the_feed_without_a_limit_cycle():
    _, plant, fine = _hold_feed(True)
    for axis in (0, 1):
        v = _speed(plant, fine, axis)
        slow = np.convolve(v, np.ones(20) / 20, mode="valid")  # 20 ms: below the 300 Hz
        assert v.mean() == pytest.approx(FEED, rel=0.02)
        assert slow.max() - slow.min() < 0.02 * FEED
        assert v.min() > 0.9 * FEED  # the table never stops


def test_the_plain_current_regulator_limit_cycles_at_the_feed():
    _, plant, fine = _hold_feed(False)
    v = _speed(plant, fine, 0)
    slow = np.convolve(v, np.ones(20) / 20, mode="valid")
    assert v.mean() == pytest.approx(FEED, rel=0.1)  # the mean speed is still right...
    assert slow.max() - slow.min() > 0.3 * FEED      # ...but it swings at low frequency
    assert v.min() < 0.1 * FEED                       # down to a standstill
    assert v.max() > 2.0 * FEED


def test_the_mistuned_analog_drive_without_adaptation_limit_cycles_at_the_feed():
    """The as-built drive: analog PI regulators, no adaptation, brush and thyristor drops.
    The mean speed still follows the reference (the speed integrator sees to it) but the
    table stops and lurches (braking with the reverse bridge between the lurches)."""
    cfg, plant, fine = _hold_feed(False, machine=str(AS_BUILT))
    assert cfg.axes["x"].regulators.implementation == "analog"
    v = _speed(plant, fine, 0)
    slow = np.convolve(v, np.ones(20) / 20, mode="valid")
    assert v.mean() == pytest.approx(FEED, rel=0.15)
    assert slow.max() - slow.min() > 0.5 * FEED
    assert v.min() < 0.1 * FEED and v.max() > 2.0 * FEED
    current = fine[:, _column("armature_current", 0)]
    assert np.mean(current == 0.0) > 0.3  # most of the time no current flows


def test_the_converter_gain_collapses_at_the_feed():
    """The slope of the mean current against the control voltage U_d0·cos α at the feed's
    operating point, from open-loop firings of the kernel, against 1/R: tens of times
    lower (the drop the adaptation exists for)."""
    from twin.analysis.studies.seed000_dcu_as_built import current_loop_gain

    g = current_loop_gain(str(AS_BUILT), "x", FEED)
    assert 0.02 < g["load_current"] < 0.2
    assert g["gain_a_per_v"] > 0.0
    assert g["drop"] > 20.0
