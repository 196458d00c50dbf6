"""``twin experiment``: the record pairs what the regulator compared, the loop has the
controller's one-period delay, and the elastic mode is found beside the converter's pulses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.controller.controller import Controller
from twin.drive import velocity_gain
from twin.errors import ConfigError
from twin.hardware.sim import SimDriver
from twin.plant import Plant
from twin.plant.model import axis_mechanics
from twin.session.experiments import run_experiment
from twin.session.run import model_options

CFG = load_machine("tomsk_xy")


def test_a_closed_loop_ramp_lags_by_v_over_kv():
    v = 5e-3
    result, rec = run_experiment(CFG, kind="ramp", axis="x", amplitude=v, duration=1.5)
    gains = Controller.from_machine(CFG, None, **model_options(CFG)).gains
    kp = gains.kp[0] if isinstance(gains.kp, tuple) else gains.kp
    k_v = kp * velocity_gain(CFG.axes["x"])
    # reference and position of the same tick: the lag of a type-1 loop, V/K_v (to within
    # one encoder count, 0.2 µm); pairing the next tick's position would read V·T less
    lag = rec["reference"][-50:] - rec["position"][-50:]
    assert np.mean(lag) == pytest.approx(v / k_v, abs=0.3e-6)
    assert result.steady_state_error == pytest.approx(v / k_v, abs=0.3e-6)
    assert abs(v * CFG.controller.period) > 10e-6  # the V·T the old pairing lost


def test_the_output_reaches_the_drive_one_period_after_its_sample():
    _, rec = run_experiment(CFG, kind="step", axis="y", amplitude=0.5e-3, duration=0.2)
    dac = rec["dac_volts"]
    assert dac[0] == 0.0  # nothing computed before the first sample
    assert dac[1] != 0.0  # the first sample's output, written at the second tick


@pytest.mark.parametrize("axis", ["x", "y"])
def test_the_elastic_mode_is_found_beside_the_converter_pulses(axis):
    result, _ = run_experiment(CFG, kind="step", axis=axis, amplitude=1.0, duration=1.0,
                               open_loop=True)
    # the experiment starts between the limit switches; the mode of the screw there
    sw = CFG.axes[axis].switches
    mech = axis_mechanics(CFG, axis, 0.5 * (sw.limit_min + sw.limit_max))
    expected = mech.locked_rotor_frequency / (2 * math.pi)
    assert result.elastic_mode == pytest.approx(expected, rel=0.03)


@pytest.mark.parametrize(("kind", "amplitude"), [("step", 0.2e-3), ("ramp", 4e-3)])
def test_a_closed_loop_experiment_is_the_controllers_own_loop_sample_for_sample(kind,
                                                                                amplitude):
    n = 160
    _, rec = run_experiment(CFG, kind=kind, axis="x", amplitude=amplitude,
                            duration=n * CFG.controller.period)
    # by hand: the twin behind SimDriver, the controller's test signal, Controller.run
    start = np.array([0.5 * (a.switches.limit_min + a.switches.limit_max)
                      for a in CFG.axes.values()])
    plant = Plant.from_machine(CFG)
    plant.reset(positions=start)
    ctrl = Controller.from_machine(CFG, None, start=start, **model_options(CFG))
    ctrl.test_signal("x", kind, amplitude)
    ctrl.run(SimDriver(plant, CFG.controller.period), max_time=n * CFG.controller.period)
    r = ctrl.record.as_arrays()
    assert len(r["t"]) == n
    assert np.array_equal(rec["position"], r["position"][:, 0] - start[0])
    assert np.array_equal(rec["reference"], r["ref_position"][:, 0] - start[0])
    assert np.array_equal(rec["dac_volts"], r["dac_volts"][:, 0])
    # compute ahead: the output of sample k is written at tick k + 1
    out = r["terms"][:, 0, :].sum(axis=1)
    assert rec["dac_volts"][0] == 0.0
    dac = CFG.axes["x"].dac
    lsb = 2.0 * dac.full_scale / 2 ** dac.bits
    np.testing.assert_allclose(rec["dac_volts"][1:], out[:-1], atol=lsb)


def test_a_step_that_trips_the_following_error_limit_is_refused_by_name():
    with pytest.raises(ConfigError, match=r"FOLLOWING_ERROR.*following_error_limit"):
        run_experiment(CFG, kind="step", axis="x", amplitude=5e-3, duration=0.2)
