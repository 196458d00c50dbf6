"""The linear axis model (for the DCU) against the nonlinear sampled drive."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from twin.config import load_machine
from twin.drive import (
    Drives,
    axis_transfer_function,
    design,
    speed_transfer_function,
    velocity_gain,
)

from .rig import simulate

PRESETS = {name: load_machine(name) for name in ("tomsk_xy", "laser_belt")}
PRESETS["tomsk_mean"] = PRESETS["tomsk_xy"].with_overrides(
    {"axes.*.converter.model": "mean"})
# the machine's own regulator settings, off their design: plant and model both follow them
_DESIGNED = design(PRESETS["tomsk_xy"].axes["y"])
PRESETS["tomsk_speed_set"] = PRESETS["tomsk_xy"].with_overrides({
    "axes.*.regulators.speed_kp": 0.7 * _DESIGNED.speed_kp,
    "axes.*.regulators.speed_ti": 1.5 * _DESIGNED.speed_ti})
PRESETS["tomsk_current_set"] = PRESETS["tomsk_xy"].with_overrides({
    "axes.*.regulators.current_kp": 0.6 * _DESIGNED.current_kp})
PRESETS["tomsk_analog"] = PRESETS["tomsk_xy"].with_overrides({
    "axes.*.regulators.implementation": "analog"})


@pytest.mark.parametrize("preset", PRESETS)
def test_gains_and_structure(preset):
    ax = PRESETS[preset].axes["x"]
    num, den = speed_transfer_function(ax)
    assert den[0] == 1.0
    assert num[-1] / den[-1] == pytest.approx(1.0 / ax.tacho.gain)  # U volts → U/K_C
    num_x, den_x = axis_transfer_function(ax)
    assert den_x[-1] == 0.0 and den_x[-2] != 0.0  # one free integrator
    k_h = velocity_gain(ax)
    assert k_h == pytest.approx(ax.transmission.ratio / ax.tacho.gain)
    assert k_h == pytest.approx(1.0 / ax.volts_per_speed)
    assert num_x[-1] / den_x[-2] == pytest.approx(k_h)
    # order: T1 filter, the SO loop (PI, current lag, integrator, tacho filter), r/s
    d = design(ax)
    assert len(den_x) - 1 == 1 + 4 + 1
    # the poles of the closed speed loop are stable and the T1 pole is there
    poles = np.roots(den)
    assert np.all(poles.real < 0.0)
    assert np.min(np.abs(poles + 1.0 / d.reference_filter)) < 1e-6 / d.reference_filter


def small_step(preset: str, amplitude: float, dt: float, load_factor: float, window: int):
    """Small-signal step of the nonlinear drive around a loaded operating point.

    The rotor runs at ``amplitude`` volts of reference against ``load_factor`` of the rated
    torque (plus the preset rotor friction), so the bridge keeps conducting in one sense and
    no limit is reached; then the reference steps by ``amplitude``. Returns the time after
    the step, the speed change and the motor-angle change, normalised to the step, and the
    speed change averaged over ``window`` updates (one converter pulse for the pulse-level
    model, whose 300 Hz torque pulses ripple the speed; 1: none).
    """
    ax = PRESETS[preset].axes["y"]
    load = load_factor * ax.motor.emf_constant * ax.motor.rated_current
    t_step = 0.3
    drives = Drives([ax], dt=dt)
    run = simulate(drives, lambda t: amplitude * (1.0 if t < t_step - 1e-9 else 2.0), 0.45,
                   load=load, coulomb=ax.mechanics.rotor_coulomb,
                   viscous=ax.mechanics.rotor_viscous, substeps=max(1, round(dt / 2e-5)))
    after = run.time > t_step + 1e-9  # records of the updates from the step on
    k = np.nonzero(after)[0][0]
    t = np.arange(np.count_nonzero(after) + 1) * dt  # record k − 1 ends at the step
    w0 = run.omega[k - 1, 0]
    dw = np.concatenate([[0.0], run.omega[after, 0] - w0]) / amplitude
    dtheta = np.concatenate([[0.0], run.angle[after, 0] - run.angle[k - 1, 0] - w0 * t[1:]])
    smooth = np.convolve(run.omega[:, 0], np.ones(window) / window, mode="same")
    dw_mean = np.concatenate([[0.0], smooth[after] - smooth[k - 1]]) / amplitude
    assert np.all(run.current[after, 0] > 0.0)  # continuous conduction throughout
    assert np.abs(run.current_reference[:, 0]).max() < drives.designs[0].current_limit
    return ax, t, dw, dtheta / amplitude, dw_mean


T_P = PRESETS["tomsk_xy"].axes["y"].converter.firing_period


# tomsk mean-value: 300 Hz regulator sampling vs T_σ = 4.3 ms costs the linear model a few
# percent. tomsk pulse-level: in continuous conduction (150 % rated torque: the boundary
# is 4.2 A·sin α) the one-pulse mean of the speed follows the design's T_ie = 2·T_p within
# 4 % (in discontinuous conduction the compensated current loop is faster at first and the
# speed then lags: 13 %; that is the drive a DCU derived from this model meets at feed
# speeds). laser (PWM at 10 kHz) needs drive updates much faster than its 0.6 ms T_σ.
# The position lag (what DCU order 1 compensates) is three times the speed tolerance, but
# 15 % for the pulse-level drive: its lag area is 12 % above the model's (the firing delay
# and the pulse-mean measurement are not exactly the T_μ = T_p lumped into the design).
@pytest.mark.parametrize(("preset", "amplitude", "dt", "load", "window", "tolerance",
                          "lag_tolerance"), [
    ("tomsk_mean", 1.0, 1e-3, 0.4, 1, 0.04, 0.12),
    ("tomsk_xy", 1.0, T_P / 10, 1.5, 10, 0.04, 0.15),
    ("laser_belt", 0.02, 5e-5, 0.4, 1, 0.01, 0.03),
    # the machine file's own settings: a slower current loop is a lumped lag R·T_ii/K_pi
    # only to first order (speed 8 %, lag area 21 %: the drive still 4 % above its final
    # speed at the end); both loops mistuned at once the linear model is off by 20 %
    ("tomsk_speed_set", 1.0, T_P / 10, 1.5, 10, 0.04, 0.15),
    ("tomsk_current_set", 1.0, T_P / 10, 1.5, 10, 0.10, 0.25),
    ("tomsk_analog", 1.0, T_P / 10, 1.5, 10, 0.05, 0.15),
])
def test_step_response_matches_the_nonlinear_drive(preset, amplitude, dt, load, window,
                                                   tolerance, lag_tolerance):
    ax, t, dw, dtheta, dw_mean = small_step(preset, amplitude, dt, load, window)
    num, den = speed_transfer_function(ax)
    _, y = signal.step((num, den), T=t)
    if window > 1:  # the same moving mean on the model, and the last half window dropped
        y = np.convolve(np.concatenate([np.zeros(window), y]), np.ones(window) / window,
                        mode="same")[window:]
        dw, y, t, dtheta = (dw_mean[:-window // 2], y[:-window // 2], t[:-window // 2],
                            dtheta[:-window // 2])
    final = 1.0 / ax.tacho.gain
    deviation = np.abs(dw - y).max() / final
    print(f"{preset}: linear vs nonlinear speed step, max deviation {deviation:.2%}")
    assert deviation < tolerance
    if not preset.endswith(("_set", "_analog")):  # slower loops: not settled in 0.15 s
        assert dw[-1] == pytest.approx(final, rel=0.01)
    # position: the table model r·θ; its deviation from the unit-velocity ramp (the lag
    # area) matches the TF's, i.e. what the DCU compensates
    num_x, den_x = axis_transfer_function(ax)
    _, x = signal.step((num_x, den_x), T=t)
    k_h = velocity_gain(ax)
    lag_model = k_h * t[-1] - x[-1]
    lag_drive = k_h * t[-1] - ax.transmission.ratio * dtheta[-1]
    assert lag_drive == pytest.approx(lag_model, rel=lag_tolerance)
