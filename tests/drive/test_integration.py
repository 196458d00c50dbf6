"""Exact current integration of the drive against a brute-force fine-step integrator, and
the independence of the results from the update interval."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.drive import Drives

from .rig import simulate

TOMSK_PULSE = load_machine("tomsk_xy")
TOMSK = TOMSK_PULSE.with_overrides({"axes.*.converter.model": "mean"})
"""The brute force here replays a held mean voltage: the mean-value model (the pulse-level
one has its own reference, ``test_pulse_converter.py``)."""
SUB = 8  # drive updates per firing period: the voltage is constant within each update


def brute_force(i0, voltage, bridge, omega_start, omega_slope, dt, k, r, l_a, *, h=1e-6):
    """Heun steps of L·di/dt = u − k·ω(t) − R·i, the bridge conducting in its sense only.

    One row per drive update: ``voltage``/``bridge`` hold over it, ω(t) = start + slope·τ.
    Returns the current at the end of each update and its average over the update.
    """
    n_sub = round(dt / h)
    h = dt / n_sub
    i = i0
    ends, means = [], []
    for u, b, w0, dw in zip(voltage, bridge, omega_start, omega_slope, strict=True):
        charge = 0.0
        if b == 0:  # pulses removed: the logic does that only at zero current
            assert i == 0.0
            ends.append(0.0)
            means.append(0.0)
            continue
        for m in range(n_sub):
            tau = m * h
            if i == 0.0 and b * (u - k * (w0 + dw * tau)) <= 0.0:
                continue  # blocked by the EMF/voltage balance

            def f(tau, i, u=u, w0=w0, dw=dw):
                return (u - k * (w0 + dw * tau) - r * i) / l_a
            k1 = f(tau, i)
            i_new = i + h * 0.5 * (k1 + f(tau + h, i + h * k1))
            if b * i_new < 0.0:
                # the bridge stops at zero: charge of the linear piece down to it
                charge += 0.5 * i * h * i / (i - i_new)
                i = 0.0
                continue
            charge += 0.5 * (i + i_new) * h
            i = i_new
        ends.append(i)
        means.append(charge / dt)
    return np.array(ends), np.array(means)


@pytest.mark.parametrize("extrapolate", [True, False])
def test_exact_integration_matches_brute_force(extrapolate):
    """Prescribed rotor speed (not coupled to the torque) and a reference that makes the
    drive reverse and conduct discontinuously; the brute force replays the drive's own
    voltage and bridge sequence."""
    ax = TOMSK.axes["y"]
    t_p = ax.converter.firing_period
    dt = t_p / SUB
    drives = Drives([ax], dt=dt, extrapolate_speed=extrapolate)
    n = round(0.12 / dt)
    t = np.arange(n) * dt
    omega = 6.0 * np.sin(2 * math.pi * 8.0 * t)
    u_ref = 0.3 * np.sin(2 * math.pi * 8.0 * t + 0.5)
    volts, bridge, current, torque = [], [], [], []
    for uk, wk in zip(u_ref, omega, strict=True):
        torque.append(drives.step(np.array([uk]), np.array([wk]))[0])
        volts.append(drives.voltage[0])
        bridge.append(drives.bridge[0])
        current.append(drives.current[0])
    bridge = np.array(bridge)
    slope = np.diff(omega, prepend=omega[0]) / dt if extrapolate else np.zeros(n)
    k = ax.motor.emf_constant
    ref_end, ref_mean = brute_force(0.0, volts, bridge, omega, slope, dt, k,
                                    ax.motor.armature_resistance,
                                    ax.motor.armature_inductance)
    current = np.array(current)
    assert {-1, 1} <= set(bridge)  # it reversed
    extinct = (current == 0.0) & (bridge != 0)
    assert extinct.any()  # and conducted discontinuously
    scale = np.abs(current).max()
    np.testing.assert_allclose(current, ref_end, atol=1e-7 * scale)
    np.testing.assert_allclose(np.array(torque) / k, ref_mean, atol=1e-7 * scale)
    np.testing.assert_array_equal(ref_end[extinct], 0.0)


@pytest.mark.parametrize("dt_fine", [1e-3 / 3, 1e-4, 1e-3 / 7])
def test_results_do_not_depend_on_the_update_interval(dt_fine):
    """Constant rotor speed, reference changing on a 1 ms grid: updating every 1 ms or every
    dt_fine gives the same currents (to rounding) and the same 1 ms torque averages."""
    ax = TOMSK.axes["y"]
    coarse = Drives([ax], dt=1e-3)
    fine = Drives([ax], dt=dt_fine)
    ratio = round(1e-3 / dt_fine)
    omega = np.array([12.0])
    rng = np.random.default_rng(3)
    for ms in range(150):
        u = np.array([rng.uniform(-1.0, 1.0) if ms % 30 == 0 else 0.4])
        tau_coarse = coarse.step(u, omega)[0]
        tau_fine = np.mean([fine.step(u, omega)[0] for _ in range(ratio)])
        assert fine.time == pytest.approx(coarse.time, abs=1e-12)
        assert fine.current[0] == pytest.approx(coarse.current[0], abs=1e-9)
        assert tau_fine == pytest.approx(tau_coarse, abs=1e-9)
        assert fine.voltage[0] == pytest.approx(coarse.voltage[0], abs=1e-9)


@pytest.mark.parametrize(("cfg", "bound"), [(TOMSK, 0.01), (TOMSK_PULSE, 0.015)],
                         ids=["mean", "pulse"])
def test_coupling_converges_with_the_update_interval(cfg, bound):
    """Rotor coupled through the interval-average torque: the 1 V step response at a 1 ms
    update differs from the 0.1 ms one by < 1 % of the final speed (the speed is
    extrapolated inside the interval; holding it would delay EMF and tacho by dt/2). The
    pulse-level converter's torque comes in pulses of about a millisecond, which a linear
    speed inside a 1 ms interval follows less well: < 1.5 %."""
    ax = cfg.axes["y"]
    runs = {}
    for dt in (1e-3, 1e-4):
        run = simulate(Drives([ax], dt=dt), 1.0, 0.2, coulomb=ax.mechanics.rotor_coulomb,
                       viscous=ax.mechanics.rotor_viscous, substeps=round(dt / 2e-5))
        runs[dt] = np.interp(np.arange(1, 201) * 1e-3, run.time, run.omega[:, 0])
    final = 1.0 / ax.tacho.gain
    deviation = np.abs(runs[1e-3] - runs[1e-4]).max() / final
    print(f"1 ms vs 0.1 ms update: max deviation {deviation:.2%} of the final speed")
    assert deviation < bound
