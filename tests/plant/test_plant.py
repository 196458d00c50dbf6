"""The plant's stepping contract: issue 2 tests 1 and 8 (plant parts), DAC, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.plant.modal import mid_travel
from twin.config import load_machine
from twin.errors import ConfigError, SimulationError
from twin.plant import Plant

MACHINES = ["tomsk_xy", "laser_belt"]


def _period(plant: Plant) -> float:
    """The controller period rounded to the drive grid (laser_belt: 3.5 ms → 4 ms)."""
    return plant.drive_dt * max(1, round(plant.config.controller.period / plant.drive_dt))


def _run_one_second(plant: Plant, command, rng) -> list:
    plant.reset(positions=mid_travel(plant.config))
    period = _period(plant)
    statuses = []
    for i in range(round(1.0 / period)):
        statuses.append(plant.step(command(i * period, rng), period))
    return statuses


@pytest.mark.parametrize("machine", MACHINES)
def test_random_dac_for_one_second_raises_no_mujoco_warning(machine):
    plant = Plant.from_machine(machine)
    full_scale = plant.config.axes["x"].dac.full_scale
    statuses = _run_one_second(plant, lambda t, rng: rng.uniform(-full_scale, full_scale, 2),
                               np.random.default_rng(1))
    assert not plant.data.warning.number.any()
    assert all(not s.warnings for s in statuses)
    assert np.isfinite(plant.data.qpos).all() and np.isfinite(plant.data.qvel).all()


@pytest.mark.parametrize("machine", MACHINES)
def test_control_noise_and_sensor_noise_raise_no_mujoco_warning(machine):
    # Menagerie's check: a smooth command plus white control noise, sensors noisy too.
    plant = Plant.from_machine(machine, noise=True, seed=3)

    def command(t, rng):
        smooth = 3.0 * np.array([math.sin(2 * math.pi * t), math.cos(2 * math.pi * t)])
        return smooth + rng.normal(0.0, 1.0, 2)

    _run_one_second(plant, command, np.random.default_rng(2))
    assert not plant.data.warning.number.any()
    assert np.isfinite(plant.truth().table_position).all()


LSB = 20.0 / 4096  # 12-bit DAC over ±10 V (seed 000, machine files): 4.8828125 mV


@pytest.mark.parametrize(("volts", "code"), [
    (0.0, 0), (0.0037, 1), (0.0024, 0), (0.0025, 1), (-0.0025, -1), (1.0, 205),
    (-3.3333, -683), (9.995, 2047), (-10.0, -2048),
])
def test_dac_quantises_to_the_12_bit_grid(volts, code):
    plant = Plant.from_machine("tomsk_xy")
    status = plant.step(np.array([volts, 0.0]), 0.5)  # ≫ the drive's reference filter
    reference = plant.truth().speed_reference
    assert reference[0] == pytest.approx(code * LSB, abs=LSB / 100)
    assert not status.saturated.any()


@pytest.mark.parametrize("volts", [10.0, 10.3, 25.0, -10.01, -1e6])
def test_dac_beyond_full_scale_saturates_and_is_flagged(volts):
    plant = Plant.from_machine("tomsk_xy")
    status = plant.step(np.array([volts, 0.5]), 0.5)
    limit = 2047 * LSB if volts > 0 else -10.0
    assert plant.truth().speed_reference[0] == pytest.approx(limit, abs=LSB / 100)
    assert status.saturated.tolist() == [True, False]
    assert not status.ok


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_dac_raises_and_changes_nothing(bad):
    plant = Plant.from_machine("tomsk_xy")
    plant.step(np.array([1.0, 1.0]), 0.01)
    before = plant.truth()
    with pytest.raises(SimulationError, match=r"dac_volts\[1\] \(y\) must be finite"):
        plant.step(np.array([0.0, bad]), 0.01)
    after = plant.truth()
    assert after.time == before.time
    np.testing.assert_array_equal(after.rotor_angle, before.rotor_angle)


def test_diverging_physics_raises_instead_of_a_silent_nan_state(tmp_path, monkeypatch):
    # A 10 ms step is far beyond the stability limit of the screw modes (the fastest: the
    # screw body between its gear and axial springs, 2.2 krad/s with the nut nearest the
    # motor). The machine file refuses it, naming the step and the mode; forced past that
    # check, the state
    # blows up, and MuJoCo's auto-reset is off so the plant must notice and say so.
    monkeypatch.chdir(tmp_path)  # MuJoCo logs the warning to ./MUJOCO_LOG.TXT
    base = Plant.from_machine("tomsk_xy").config
    with pytest.raises(ConfigError, match=r"simulation.timestep: 0.01 s is too long for "
                       r"the elastic mode of axis x: ω = 2212 rad/s"):
        base.with_overrides({"simulation.timestep": 1e-2, "simulation.drive_substeps": 1,
                             "controller.period": 1e-2})
    cfg = base.with_overrides({"simulation.drive_substeps": 1, "controller.period": 1e-2})
    object.__setattr__(cfg.simulation, "timestep", 1e-2)    # past the schema's check
    plant = Plant(cfg)
    with pytest.raises(SimulationError, match="diverged"):
        for _ in range(1000):
            plant.step(np.array([5.0, -5.0]), 1e-2)


@pytest.mark.parametrize("duration", [0.0, -1e-3, 1.5e-3, 2.5e-4, math.nan])
def test_duration_must_be_a_positive_multiple_of_the_drive_interval(duration):
    plant = Plant.from_machine("tomsk_xy")
    with pytest.raises(ValueError, match="multiple of the drive interval"):
        plant.step(np.zeros(2), duration)


@pytest.mark.parametrize("shape", [(3,), (1,)])
def test_dac_shape_is_checked(shape):
    with pytest.raises(ValueError, match="2 entries"):
        Plant.from_machine("tomsk_xy").step(np.zeros(shape), 1e-3)


def test_plant_is_deterministic_and_step_splitting_does_not_matter():
    a, b = Plant.from_machine("tomsk_xy"), Plant.from_machine("tomsk_xy")
    rng = np.random.default_rng(5)
    commands = rng.uniform(-5, 5, (40, 2))
    for u in commands:
        a.step(u, 5e-3)
        for _ in range(5):
            b.step(u, 1e-3)
    ta, tb = a.truth(), b.truth()
    for field in ("table_position", "rotor_angle", "armature_current", "screw_deflection"):
        np.testing.assert_array_equal(getattr(ta, field), getattr(tb, field))
    np.testing.assert_array_equal(a.read().encoder_counts, b.read().encoder_counts)


def test_truth_is_consistent_with_the_model_kinematics():
    plant = Plant.from_machine("laser_belt")
    plant.step(np.array([2.0, -1.0]), 0.05)
    t = plant.truth()
    r = np.array([plant.config.axes[a].transmission.ratio for a in ("x", "y")])
    np.testing.assert_allclose(t.screw_deflection, r * t.rotor_angle - t.table_position,
                               atol=1e-12)
    assert t.time == pytest.approx(0.05)
    assert plant.time == pytest.approx(0.05)
    assert plant.drives.time == pytest.approx(plant.time)


def test_sensor_noise_follows_the_machine_file_seeded_and_can_be_silenced():
    cfg = Plant.from_machine("tomsk_xy").config.with_overrides(
        {"axes.*.encoder.noise_counts": 2.0, "axes.*.tacho.noise": 0.01})
    quiet = Plant(cfg, noise=False)
    assert len({tuple(quiet.read().encoder_counts) for _ in range(20)}) == 1
    noisy = [Plant(cfg, seed=7) for _ in range(2)]  # the machine's noise: on by default
    seqs = [[tuple(p.read().encoder_counts) for _ in range(50)] for p in noisy]
    assert seqs[0] == seqs[1]  # same seed, same noise
    assert len(set(seqs[0])) > 1
    spread = np.array(seqs[0]) - np.array(quiet.read().encoder_counts)
    assert 1.0 < spread.std() < 3.0  # rms 2 counts, rounded


def test_reset_places_the_tables_and_rejects_positions_outside_the_travel():
    plant = Plant.from_machine("tomsk_xy")
    plant.step(np.array([3.0, 3.0]), 0.05)
    plant.reset(positions=np.array([0.1, 0.05]))
    t = plant.truth()
    np.testing.assert_allclose(t.table_position, [0.1, 0.05])
    np.testing.assert_allclose(t.screw_deflection, 0.0, atol=1e-15)
    assert t.time == 0.0 and not t.rotor_speed.any()
    with pytest.raises(ValueError, match="within the travel"):
        plant.reset(positions=np.array([0.5, 0.05]))
    with pytest.raises(ValueError, match="keyframe"):
        plant.reset("nowhere")


@pytest.mark.parametrize(("gain_error", "offset"), [(0.1, 0.0), (0.0, 0.05), (-0.2, -0.03)])
def test_the_plants_dac_has_its_own_gain_error_and_offset(gain_error, offset):
    """The drive turns at (code·LSB·(1 + gain error) + offset)/K_C: the real output stage,
    which the controller's DAC setting does not know."""
    cfg = load_machine("tomsk_xy").with_overrides(
        {"axes.x.dac.gain_error": gain_error, "axes.x.dac.offset": offset})
    plant = Plant(cfg)
    volts = 205 * LSB  # one code grid point: 1.00098 V
    plant.step(np.array([volts, 0.0]), 0.5)
    expected = volts * (1.0 + gain_error) + offset
    assert plant.truth().speed_reference[0] == pytest.approx(expected, abs=1e-6)
    omega = plant.truth().rotor_speed[0]
    assert omega == pytest.approx(expected / cfg.axes["x"].tacho.gain, rel=0.02)


def test_tacho_ripple_rides_on_the_tacho_signal_at_its_harmonic():
    from twin.drive import Drives

    ax = load_machine("tomsk_xy").with_overrides(
        {"axes.y.tacho.ripple": [[2.0, 3.0]]}).axes["y"]
    drives = Drives([ax], dt=1e-3)
    omega = 20.0
    tacho = []
    for k in range(1000):  # rotor held at 20 rad/s, angle advancing
        drives.step(np.array([0.0]), np.array([omega]), np.array([omega * k * 1e-3]))
        tacho.append(drives.tacho_volts[0])
    tacho = np.array(tacho[200:])
    mean = ax.tacho.gain * omega
    assert tacho.mean() == pytest.approx(mean, rel=0.01)
    # 3 % at twice the rotation (40 rad/s, far below the 1 ms filter's corner)
    assert (tacho.max() - tacho.min()) / 2 == pytest.approx(0.03 * mean, rel=0.05)


def test_the_machines_tacho_noise_reaches_a_twin_run(tmp_path):
    from twin.session.run import RunSpec, run

    def tacho(noise, seed=0):
        spec = RunSpec(builtin="spline_line", overrides={"axes.*.tacho.noise": noise,
                                                         "simulation.seed": seed})
        return run(spec, out_dir=tmp_path, rerun="none").record["tacho_volts"][:, 0]

    clean, noisy, again, other = tacho(0.0), tacho(0.02), tacho(0.02), tacho(0.02, seed=1)
    assert np.std(noisy - clean) > 0.005               # honoured, not silently ignored
    np.testing.assert_array_equal(noisy, again)         # and seeded
    assert not np.array_equal(noisy, other)


@pytest.mark.parametrize(("joint", "axis", "what"), [("y_rotor", "y", "velocity"),
                                                      ("x", "x", "table position")])
def test_a_diverged_plant_names_the_axis_and_the_quantity(joint, axis, what):
    """The schema keeps the physics step inside what it can integrate; should the state
    still leave the finite numbers, the error says where (the drive checks the rotor speed
    it is given; the plant checks the table and every joint)."""
    plant = Plant.from_machine("tomsk_xy")
    m = plant.model
    j = m.joint(joint).id
    if what == "velocity":
        plant.data.qvel[m.jnt_dofadr[j]] = np.nan
    else:
        plant.data.qpos[m.jnt_qposadr[j]] = np.inf
    with pytest.raises(SimulationError, match=f"(axis|drive) {axis}: .*(speed|{what})"):
        plant.step(np.zeros(2), 0.005)
