"""The Drives object as the plant uses it: construction, bad input, enable, faults, noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.drive import Drives
from twin.errors import ConfigError, SimulationError

from .rig import simulate

TOMSK = load_machine("tomsk_xy")
LASER = load_machine("laser_belt")


def _pair(cfg=TOMSK, **kw) -> Drives:
    return Drives([cfg.axes["x"], cfg.axes["y"]], dt=1e-3, **kw)


def _state(d: Drives) -> dict[str, np.ndarray]:
    return {name: getattr(d, name) for name in (
        "current", "voltage", "tacho_volts", "speed_reference", "bridge", "firing_angle",
        "current_reference")}


def test_readouts_have_the_documented_shapes_and_time_advances():
    d = _pair()
    assert d.time == 0.0
    for name, value in _state(d).items():
        assert value.shape == (2,), name
    assert d.bridge.dtype.kind == "i"
    assert np.all(np.isnan(d.firing_angle))  # blocked at rest
    tau = d.step(np.array([1.0, -1.0]), np.zeros(2))
    assert tau.shape == (2,)
    for _ in range(9):
        d.step(np.array([1.0, -1.0]), np.zeros(2))
    assert d.time == pytest.approx(10e-3)
    tau[:] = 99.0  # the returned array is the caller's
    assert np.all(d.torque != 99.0)


@pytest.mark.parametrize(("u", "w", "what", "axis"), [
    ([np.nan, 0.0], [0.0, 0.0], "speed reference", "x"),
    ([0.0, np.inf], [0.0, 0.0], "speed reference", "y"),
    ([0.0, 0.0], [0.0, -np.inf], "rotor speed", "y"),
    ([0.0, 0.0], [np.nan, 0.0], "rotor speed", "x"),
])
def test_non_finite_input_raises_and_changes_nothing(u, w, what, axis):
    d = _pair()
    for _ in range(20):
        d.step(np.array([1.0, 1.0]), np.array([3.0, 3.0]))
    before = _state(d)
    t = d.time
    with pytest.raises(SimulationError, match=rf"drive {axis}: {what}.* not finite"):
        d.step(np.array(u), np.array(w))
    assert d.time == t
    for name, value in _state(d).items():
        np.testing.assert_array_equal(value, before[name], err_msg=name)


def test_wrong_shapes_and_bad_settings_are_rejected():
    d = _pair()
    with pytest.raises(ValueError, match="shape"):
        d.step(np.zeros(3), np.zeros(2))
    with pytest.raises(ConfigError, match="dt"):
        Drives([TOMSK.axes["x"]], dt=0.0)
    with pytest.raises(ConfigError, match="dt"):
        Drives([TOMSK.axes["x"]], dt=math.nan)
    with pytest.raises(ConfigError, match="moving_masses"):
        Drives([TOMSK.axes["x"]], dt=1e-3, moving_masses=[1.0, 2.0])
    with pytest.raises(ConfigError, match="axes"):
        Drives([], dt=1e-3)


def test_from_machine_uses_the_cross_table_masses_and_simulation_rate():
    d = Drives.from_machine(LASER)
    assert d.dt == pytest.approx(LASER.simulation.timestep * LASER.simulation.drive_substeps)
    m = LASER.moving_masses()
    r = LASER.axes["x"].transmission.ratio
    assert d.designs[0].inertia == pytest.approx(
        LASER.axes["x"].mechanics.rotor_inertia + m["x"] * r * r)
    assert d.names == ("x", "y")


@pytest.mark.parametrize("cfg", [TOMSK, LASER], ids=["thyristor", "pwm"])
def test_disable_forces_the_current_to_zero_and_resets_the_regulators(cfg):
    ax = cfg.axes["y"]
    d = Drives([ax], dt=1e-4)
    omega = np.array([0.5 * ax.motor.rated_speed])
    for _ in range(500):  # loaded: a flowing current and a wound-up speed integrator
        d.step(np.array([5.0]), omega)
    i0 = d.current[0]
    assert abs(i0) > 0.5
    d.enable(False)
    currents, bridges = [], []
    for _ in range(300):
        d.step(np.array([5.0]), omega)
        currents.append(d.current[0])
        bridges.append(d.bridge[0])
    currents = np.array(currents)
    assert currents[-1] == 0.0 and bridges[-1] == 0
    first_zero = np.nonzero(currents == 0.0)[0][0]
    assert np.all(currents[first_zero:] == 0.0)  # no reversal, no restart
    # forced down against the blocking voltage (inverter end stop / DC link), not coasting:
    # next firing instant + L·|i0|/U_block, the EMF only helping
    u_block = -d.designs[0].voltage_range[0]
    bound = ax.converter.firing_period + ax.motor.armature_inductance * abs(i0) / u_block
    assert first_zero * d.dt <= bound + d.dt
    assert d.voltage[0] == 0.0 and d.speed_reference[0] == 0.0 and d.current_reference[0] == 0.0
    d.enable(True)  # re-enabled: starts from a reset regulator and a filtered reference
    d.step(np.array([5.0]), omega)
    assert 0.0 < d.speed_reference[0] < 1.0


def test_sustained_current_limit_trips_and_latches():
    ax = TOMSK.axes["y"]
    d = Drives([ax], dt=1e-3, overload_time=0.2)
    stalled = np.zeros(1)  # blocked rotor, full reference: current limit
    for _ in range(150):
        d.step(np.array([10.0]), stalled)
    assert not d.fault[0]
    # the pulse mean the regulator measures (the instantaneous current carries the ripple)
    assert d.measured_current[0] == pytest.approx(ax.motor.current_limit, rel=0.05)
    for _ in range(100):
        d.step(np.array([10.0]), stalled)
    assert d.fault[0]
    for _ in range(50):
        d.step(np.array([10.0]), stalled)
    assert d.current[0] == 0.0 and d.bridge[0] == 0  # latched: blocked
    d.enable(False)
    assert not d.fault[0]
    d.enable(True)
    for _ in range(10):  # the next firing instants after the restart
        d.step(np.array([10.0]), stalled)
    assert d.current[0] > 0.0


def test_reset_returns_to_time_zero():
    d = _pair()
    fresh = _state(d)
    for _ in range(50):
        d.step(np.array([2.0, -2.0]), np.array([4.0, -4.0]))
    d.reset()
    assert d.time == 0.0
    for name, value in _state(d).items():
        np.testing.assert_array_equal(value, fresh[name], err_msg=name)
    np.testing.assert_array_equal(d.step(np.ones(2), np.zeros(2)),
                                  _pair().step(np.ones(2), np.zeros(2)))


def test_tacho_noise_is_seeded_and_off_by_default():
    cfg = TOMSK.with_overrides({"axes.*.tacho.noise": 0.01})

    def tacho(drives: Drives) -> np.ndarray:
        run = simulate(drives, np.array([1.0, 1.0]), 0.05)
        return run.tacho

    a = tacho(_pair(cfg, rng=np.random.default_rng(7)))
    b = tacho(_pair(cfg, rng=np.random.default_rng(7)))
    c = tacho(_pair(cfg, rng=np.random.default_rng(8)))
    clean = tacho(_pair())
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    noise = (a - clean)[10:]  # the loop reacts to the noise, but the ADC sees it directly
    assert 0.005 < noise.std() < 0.03
    np.testing.assert_array_equal(clean, tacho(_pair()))
