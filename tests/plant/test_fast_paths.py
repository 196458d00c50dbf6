"""The plant's per-period fast paths give exactly what the checked paths give."""

import os

import numpy as np
import pytest

from twin.controller.io import Inputs
from twin.plant import TRUTH_FIELDS, Plant


@pytest.mark.parametrize("machine", ["tomsk_xy", "laser_belt"])
@pytest.mark.parametrize("preset", [None, (2**32 - 300, 5)])
def test_a_sample_is_what_the_plant_state_says(machine, preset):
    """The one read path against the state, computed here with numpy: counters from the
    rotor angles (with the preset, wrapped to 32 bits), the ADC's tacho volts, drive ready,
    the plant time."""
    plant = Plant.from_machine(machine)
    plant.reset(encoder_preset=None if preset is None else np.array(preset))
    cpr = np.array([plant.config.axes[a].encoder.counts_per_rev for a in ("x", "y")])
    offset = np.zeros(2, np.int64) if preset is None else \
        np.array(preset, np.int64) - np.floor(plant.truth().rotor_angle * cpr / (2 * np.pi)
                                              ).astype(np.int64)
    inputs = Inputs()
    dac = np.array([2.0, -1.5])
    for _ in range(60):                      # crosses the 32-bit wrap with the preset
        plant.step(dac, plant.config.controller.period)
        plant.read_into(inputs)
        raw = np.floor(plant.truth().rotor_angle * cpr / (2 * np.pi)).astype(np.int64)
        np.testing.assert_array_equal(inputs.encoder_counts, (raw + offset) & (2**32 - 1))
        np.testing.assert_array_equal(inputs.tacho_volts, plant.drives.tacho_volts)
        assert inputs.drive_ready == (not plant.drives.fault.any())
        assert inputs.time == plant.time
        r = plant.read()
        np.testing.assert_array_equal(r.encoder_counts, inputs.encoder_counts)


def test_a_fault_acknowledged_by_disabling_shows_in_the_next_sample():
    from twin.drive import layout

    plant = Plant.from_machine("tomsk_xy")
    plant.enable(True)
    plant.step(np.zeros(2), plant.config.controller.period)
    plant.drives.kernel_arrays()[1][:, layout.S_FAULT] = 1.0   # an overload trip latched
    plant.enable(True)                               # (re-reads the state, keeps the trip)
    assert not plant.read().drive_ready
    plant.enable(False)                              # acknowledges it
    assert plant.read().drive_ready


def test_truth_row_equals_truth():
    plant = Plant.from_machine("tomsk_xy")
    plant.step(np.array([1.0, 0.5]), 0.05)
    t = plant.truth()
    row = plant.truth_row()
    expected = np.concatenate([getattr(t, name) for name, _ in TRUTH_FIELDS])
    np.testing.assert_allclose(row, expected, rtol=0, atol=1e-15)
    assert len(row) == sum(n for _, n in TRUTH_FIELDS)


def test_step_into_equals_step():
    a, b = Plant.from_machine("tomsk_xy").drives, Plant.from_machine("tomsk_xy").drives
    u, w, th = np.array([1.0, -2.0]), np.array([3.0, -1.0]), np.array([0.3, 2.0])
    out = np.zeros(2)
    for _ in range(50):
        tau = a.step(u, w, th)
        b.step_into(u, w, out, th)
        np.testing.assert_array_equal(tau, out)


# every path of the plant loop: the presets, and a machine with noise, tacho ripple,
# break-away friction and lost motion (passive forces before every physics step)
_FAULTY = {"axes.*.tacho.noise": 0.002, "axes.*.tacho.ripple": [[1.0, 2.0], [8.0, 1.0]],
           "axes.*.mechanics.slide_breakaway": 40.0, "axes.*.mechanics.rotor_breakaway": 0.05,
           "axes.*.transmission.backlash": 10e-6}


@pytest.mark.parametrize("machine", ["tomsk_xy", "laser_belt", "faulty"])
def test_compiled_loop_is_bit_identical_to_the_python_loop(machine):
    from twin.config import load_machine
    from twin.plant import loop as plant_loop

    assert plant_loop.available()
    cfg = load_machine("tomsk_xy").with_overrides(_FAULTY) if machine == "faulty" \
        else load_machine(machine)
    fast, slow = Plant(cfg, seed=5), Plant(cfg, seed=5)
    slow._compiled = False
    period = fast.config.controller.period
    rng = np.random.default_rng(3)
    for _ in range(200):
        dac = rng.uniform(-3.0, 3.0, 2)
        sf, ss = fast.step(dac, period), slow.step(dac, period)
        np.testing.assert_array_equal(sf.limit_hit, ss.limit_hit)
    np.testing.assert_array_equal(fast.data.qpos, slow.data.qpos)
    np.testing.assert_array_equal(fast.data.qvel, slow.data.qvel)
    np.testing.assert_array_equal(fast.drives.snapshot(), slow.drives.snapshot())
    np.testing.assert_array_equal(fast.fine, slow.fine)
    assert fast.time == slow.time and fast.drives.time == slow.drives.time


def test_compiled_loop_reports_a_nan_like_the_python_loop():
    from twin.errors import SimulationError

    plant = Plant.from_machine("tomsk_xy")
    plant.data.qvel[:] = np.nan                  # rotor speed not finite
    with pytest.raises(SimulationError, match="not finite"):
        plant.step(np.array([1.0, 0.0]), plant.config.controller.period)


def _open_loop_case(seed: int):
    """A random machine (a preset, or tomsk_xy with every passive force and random R, J,
    friction) and a random open-loop sequence: each axis starting within a millimetre of a
    switch edge (home or the lower limit) and driven across it, the enable dropped for
    random stretches, ticks of 1-3 drive intervals."""
    from twin.config import load_machine

    rng = np.random.default_rng(seed)
    kind = ("tomsk_xy", "laser_belt", "faulty")[seed % 3]
    cfg = load_machine("laser_belt" if kind == "laser_belt" else "tomsk_xy")
    if kind == "faulty":
        cfg = cfg.with_overrides({**_FAULTY, "axes.*.motor.armature_resistance":
                                  float(rng.uniform(1.5, 3.0)),
                                  "axes.*.mechanics.rotor_inertia":
                                  float(rng.uniform(0.7e-3, 1.5e-3))})
    n = int(rng.integers(150, 300))
    starts, dac = [], np.empty((n, 2))
    for k, a in enumerate(("x", "y")):
        sw = cfg.axes[a].switches
        edge = sw.home if rng.random() < 0.5 else sw.limit_min
        side = rng.choice([-1.0, 1.0])
        starts.append(max(edge - side * rng.uniform(1e-4, 1e-3), sw.limit_min / 2))
        walk = np.cumsum(rng.normal(0.0, 0.2, n))
        dac[:, k] = np.clip(side * (2.0 + walk), -9.0, 9.0)
    enable = np.ones(n, bool)
    for _ in range(int(rng.integers(0, 3))):
        k0 = int(rng.integers(1, n - 5))
        enable[k0:k0 + int(rng.integers(1, 20))] = False
    return cfg, np.array(starts), dac, enable, rng.integers(1, 4, n)


@pytest.mark.parametrize("seed", range(3) if os.environ.get("CI") else range(9))
def test_an_open_loop_run_is_its_ticks_one_by_one(seed):
    """``Plant.run_open_loop`` (the compiled ticks) against the same ticks run here one by
    one through ``read_into``, ``enable`` and ``step``: the samples, the state, the
    switches, the drive-rate samples and the clock, bit for bit."""
    cfg, starts, dac, enable, intervals = _open_loop_case(seed)
    fast, slow = Plant(cfg, noise=False), Plant(cfg, noise=False)
    for p in (fast, slow):
        p.reset(positions=starts)
    counts, tacho = fast.run_open_loop(dac, enable, intervals)
    inputs = Inputs()
    for k in range(len(dac)):
        slow.read_into(inputs)
        np.testing.assert_array_equal(counts[k], inputs.encoder_counts)
        np.testing.assert_array_equal(tacho[k], inputs.tacho_volts)
        if enable[k] != slow.drives.enabled:
            slow.enable(bool(enable[k]))
        slow.step(dac[k], int(intervals[k]) * slow.drive_dt)
    np.testing.assert_array_equal(fast.data.qpos, slow.data.qpos)
    np.testing.assert_array_equal(fast.data.qvel, slow.data.qvel)
    np.testing.assert_array_equal(fast.drives.snapshot(), slow.drives.snapshot())
    np.testing.assert_array_equal(fast.fine, slow.fine)
    np.testing.assert_array_equal(fast.drain_fine(), slow.drain_fine())
    assert fast.time == slow.time and fast.drives.time == slow.drives.time
    a, b = fast.read(), slow.read()
    for name in ("encoder_counts", "tacho_volts", "limit_min", "limit_max", "home"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert [m.pending for m in fast._monitors] == [m.pending for m in slow._monitors]


def test_an_open_loop_run_stops_on_a_request_that_is_not_finite_as_a_step_does():
    from twin.errors import SimulationError

    plant = Plant.from_machine("tomsk_xy", noise=False)
    dac = np.full((20, 2), 0.5)
    dac[12, 1] = np.nan
    with pytest.raises(SimulationError, match=r"dac_volts\[1\] \(y\) must be finite"):
        plant.run_open_loop(dac, np.ones(20, bool), np.full(20, 5))
    assert plant.time == pytest.approx(12 * plant.config.controller.period)
