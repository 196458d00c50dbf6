"""The linear axis model (the controller's belief of the drive) against the nonlinear
sampled drive, and its polynomials against the block diagram they stand for."""

from __future__ import annotations

import os

import numpy as np
import pytest
from scipy import signal

from twin.config import load_machine
from twin.drive import (
    Drives,
    axis_transfer_function,
    current_transfer_function,
    design,
    speed_transfer_function,
    velocity_gain,
)

from .rig import simulate

PRESETS = {name: load_machine(name) for name in ("tomsk_xy", "laser_belt")}
PRESETS["tomsk_mean"] = PRESETS["tomsk_xy"].with_overrides(
    {"axes.*.converter.model": "mean"})
PRESETS["tomsk_analog"] = PRESETS["tomsk_xy"].with_overrides(
    {"axes.*.regulators.implementation": "analog"})
TOMSK = PRESETS["tomsk_xy"]
T_P = TOMSK.axes["y"].converter.firing_period


def mistuned(rng: np.random.Generator, analog: bool) -> dict:
    """Overrides of a random tomsk_xy drive as a commissioning engineer may leave it: all
    four PI settings off their design at once (gains ×0.5-1.5, integral times ×0.5-2),
    the analog current filter 0.3-2 ms, and a random rotor, mains and armature circuit."""
    d = design(TOMSK.axes["y"])
    out = {"axes.*.regulators.current_kp": d.current_kp * rng.uniform(0.5, 1.5),
           "axes.*.regulators.current_ti": d.current_ti * rng.uniform(0.5, 2.0),
           "axes.*.regulators.speed_kp": d.speed_kp * rng.uniform(0.5, 1.5),
           "axes.*.regulators.speed_ti": d.speed_ti * rng.uniform(0.5, 2.0),
           "axes.*.mechanics.rotor_inertia": 1e-3 * rng.uniform(0.5, 2.0),
           "axes.*.converter.mains_deviation": rng.uniform(-0.05, 0.05),
           "axes.*.converter.thyristor_resistance": rng.uniform(0.0, 0.05),
           "axes.*.converter.smoothing_inductance": rng.choice([0.0, rng.uniform(0.0, 0.01)])}
    if analog:
        out["axes.*.regulators.implementation"] = "analog"
        out["axes.*.regulators.current_filter"] = rng.uniform(0.3e-3, 2e-3)
    return {k: (v if isinstance(v, str) else float(v)) for k, v in out.items()}


def mistuned_drives(seed: int, count: int) -> list[tuple[str, object]]:
    """``count`` random mistuned tomsk_xy Y axes, digital and analog in turn. A draw whose
    speed loop would not settle within the test's 0.3 s (a pole slower than 8/s, or an
    unstable one: the engineer would have retuned it) is drawn again."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        analog = len(out) % 2 == 1
        ax = TOMSK.with_overrides(mistuned(rng, analog)).axes["y"]
        if np.roots(speed_transfer_function(ax)[1]).real.max() < -8.0:
            out.append(("analog" if analog else "digital", ax))
    return out


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
    # order: T1, the speed PI and the rotor (s²), the armature (s·(L s + R)), the dead
    # time, the current measurement (not for the mean-value model), the tacho filter, r/s
    d = design(ax)
    lags = 1 + (d.model == "pulse") + (d.tacho_filter > 0.0)
    assert len(den_x) - 1 == 1 + 2 + 2 + lags + 1
    # the poles of the closed speed loop are stable and the T1 pole is there
    poles = np.roots(den)
    assert np.all(poles.real < 0.0)
    assert np.min(np.abs(poles + 1.0 / d.reference_filter)) < 1e-6 / d.reference_filter
    num_i, den_i = current_transfer_function(ax)
    assert num_i[-1] / den_i[-1] == pytest.approx(1.0)   # EMF compensated: I = I* at DC


def test_the_polynomials_are_the_block_diagram():
    """At random frequencies, the loop equations solved as a linear system (complex
    arithmetic, no polynomial algebra) give what the transfer functions give: random
    settings, both implementations, the mean-value model and PWM, with and without the tacho
    filter."""
    rng = np.random.default_rng(11)
    axes = [ax for _, ax in mistuned_drives(11, 6)]
    axes += [PRESETS[p].with_overrides({"axes.y.tacho.filter_time_constant": 0.0}).axes["y"]
             for p in ("tomsk_xy", "tomsk_mean", "laser_belt")]
    for ax in axes:
        d = design(ax)
        g = 1.0 + ax.converter.mains_deviation if ax.converter.kind == "thyristor" else 1.0
        t_v = 0.5 * d.sampling_period
        t_m = {"analog": d.current_filter, "pulse": 0.5 * d.sampling_period}.get(
            d.implementation if d.implementation == "analog" else d.model, 0.0)
        for w in rng.uniform(0.5, 3000.0, 5):
            s = 1j * w
            dead = g / (t_v * s + 1)
            meas = 1 / (t_m * s + 1)
            filt = 1 / (d.tacho_filter * s + 1)
            pi_i = d.current_kp * (d.current_ti * s + 1) / (d.current_ti * s)
            pi_w = d.speed_kp * (d.speed_ti * s + 1) / (d.speed_ti * s)
            k, j = d.emf_constant, d.inertia
            # unknowns I, ω, I* for a unit reference after the T1 filter:
            # (L s + R)·I − dead·(k·filt·ω + pi_i·(I* − meas·I)) + k·ω = 0
            # J·s·ω − k·I = 0
            # I* + pi_w·K_C·filt·ω = pi_w
            a = np.array([[d.inductance * s + d.resistance + dead * pi_i * meas,
                           k - dead * k * filt, -dead * pi_i],
                          [-k, j * s, 0.0],
                          [0.0, pi_w * d.tacho_gain * filt, 1.0]])
            omega = np.linalg.solve(a, np.array([0.0, 0.0, pi_w]))[1]
            num, den = speed_transfer_function(ax)
            got = np.polyval(num, s) / np.polyval(den, s) * (d.reference_filter * s + 1)
            assert got == pytest.approx(omega, rel=1e-9)
            # the current loop alone: I* given, I and ω unknown
            b = a[:2, :2]
            i_only = np.linalg.solve(b, np.array([dead * pi_i, 0.0]))[0]
            num_i, den_i = current_transfer_function(ax)
            assert np.polyval(num_i, s) / np.polyval(den_i, s) == pytest.approx(i_only,
                                                                                 rel=1e-9)


def step_pair(ax, amplitude: float, dt: float, load_factor: float, window: int,
              *, step: float = 0.5, settle: float = 0.3, span: float = 0.15):
    """Small-signal step response of the nonlinear drive about a loaded operating point.

    The rotor runs at ``amplitude`` volts of reference against ``load_factor`` of the rated
    torque (plus the preset's rotor friction) for ``settle`` seconds; then the reference
    steps by +``step``·amplitude in one run and by −``step``·amplitude in another. Half
    their difference is the response's odd part: what a linear model stands for (the
    start-up transient, the pulses' ripple at the operating point and the even part of the
    converter's nonlinearity cancel; the firing unit fires a rising demand a period later
    than a falling one). Both runs must stay in continuous conduction and below the current
    limit after the step. Returns the time after the step, the speed change averaged over
    ``window`` updates (one converter pulse), and the motor-angle change, each per volt of
    step.
    """
    load = load_factor * ax.motor.emf_constant * ax.motor.rated_current
    runs = []
    for sign in (1.0, -1.0):
        drives = Drives([ax], dt=dt)
        runs.append(simulate(
            drives, lambda t, s=sign: amplitude * (1.0 + s * step * (t > settle - 1e-9)),
            settle + span, load=load, coulomb=ax.mechanics.rotor_coulomb,
            viscous=ax.mechanics.rotor_viscous, substeps=max(1, round(dt / 2e-5))))
        after = runs[-1].time > settle + 1e-9
        assert np.all(runs[-1].current[after, 0] > 0.0)  # continuous conduction throughout
        assert np.abs(runs[-1].current_reference[after, 0]).max() < \
            drives.designs[0].current_limit
    scale = 2.0 * step * amplitude
    t = np.arange(np.count_nonzero(after) + 1) * dt  # the record before `after` is the step
    dw = (runs[0].omega[:, 0] - runs[1].omega[:, 0]) / scale
    dw = np.convolve(dw, np.ones(window) / window, mode="same")
    dtheta = (runs[0].angle[:, 0] - runs[1].angle[:, 0]) / scale
    return (t, np.concatenate([[0.0], dw[after]]), np.concatenate([[0.0], dtheta[after]]))


def deviation_from_model(ax, t, dw, dtheta, window: int) -> tuple[float, float]:
    """(largest speed deviation over the final speed, relative error of the position lag
    area) of the drive's response against the linear model's."""
    num, den = speed_transfer_function(ax)
    _, y = signal.step((num, den), T=t)
    if window > 1:  # the same moving mean on the model, and the last half window dropped
        y = np.convolve(np.concatenate([np.zeros(window), y]), np.ones(window) / window,
                        mode="same")[window:]
        t, dw, y, dtheta = (a[:-window // 2] for a in (t, dw, y, dtheta))
    final = 1.0 / ax.tacho.gain
    deviation = np.abs(dw - y).max() / final
    # position: the table model r·θ; its deviation from the unit-velocity ramp (the lag
    # area) against the TF's, i.e. what the DCU compensates
    num_x, den_x = axis_transfer_function(ax)
    _, x = signal.step((num_x, den_x), T=t)
    k_h = velocity_gain(ax)
    lag_model = k_h * t[-1] - x[-1]
    lag_drive = k_h * t[-1] - ax.transmission.ratio * dtheta[-1]
    return deviation, lag_drive / lag_model - 1.0


# tomsk mean-value: 300 Hz regulator sampling vs T_σ = 4.3 ms. tomsk pulse-level (digital
# and analog): in continuous conduction (150 % rated torque: the boundary is 4.2 A·sin α)
# the one-pulse mean of the speed. laser (PWM at 10 kHz) needs drive updates much faster
# than its 0.6 ms T_σ. Measured: 0.7 %, 0.4 %, 0.6 %, 0.2 % (lag areas within 0.5 %).
@pytest.mark.parametrize(("preset", "amplitude", "dt", "load", "window", "span", "tolerance"), [
    ("tomsk_mean", 1.0, 1e-3, 0.4, 1, 0.15, 0.015),
    ("tomsk_xy", 1.0, T_P / 10, 1.5, 10, 0.15, 0.01),
    ("tomsk_analog", 1.0, T_P / 10, 1.5, 10, 0.15, 0.01),
    ("laser_belt", 0.02, 5e-5, 0.4, 1, 0.03, 0.01),
])
def test_step_response_matches_the_nonlinear_drive(preset, amplitude, dt, load, window, span,
                                                   tolerance):
    ax = PRESETS[preset].axes["y"]
    t, dw, dtheta = step_pair(ax, amplitude, dt, load, window, settle=2 * span, span=span)
    deviation, lag_error = deviation_from_model(ax, t, dw, dtheta, window)
    print(f"{preset}: linear vs nonlinear speed step, max deviation {deviation:.2%}, "
          f"lag area {lag_error:+.2%}")
    assert deviation < tolerance
    assert abs(lag_error) < 0.02


MISTUNED = 2 if os.environ.get("CI") else 16


@pytest.mark.slow
@pytest.mark.parametrize("k", range(MISTUNED))
def test_the_belief_follows_a_mistuned_drive(k):
    """Random settings off their design, both loops at once, digital and analog (seeded;
    the full run draws 16, CI the first 2): the written-out current loop follows the
    pulse-level drive in continuous conduction (measured: within 1.4 % of the final speed,
    lag areas within 1.5 %; the first-order lag R·T_ii/K_pi it replaces was 1.3-9.4 % off)."""
    kind, ax = mistuned_drives(29, MISTUNED)[k]
    t, dw, dtheta = step_pair(ax, 1.0, T_P / 10, 1.5, 10)
    deviation, lag_error = deviation_from_model(ax, t, dw, dtheta, 10)
    print(f"{kind} {k}: max deviation {deviation:.2%}, lag area {lag_error:+.2%}")
    assert deviation < 0.02
    assert abs(lag_error) < 0.03
