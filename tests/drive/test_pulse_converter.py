"""The pulse-level thyristor converter against an independent reference (solve_ivp of the
same circuit with zero-crossing events), and against the closed-form boundary between
continuous and discontinuous conduction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.drive import Drives
from twin.drive.dcm import boundary_current

from .pulse_reference import Circuit, replay
from .rig import simulate

TOMSK = load_machine("tomsk_xy")
AX = TOMSK.axes["y"]
T_P = AX.converter.firing_period
DT = T_P / 7.3  # intervals not commensurate with the pulses: events fall inside them


def _circuit(ax) -> Circuit:
    conv, motor = ax.converter, ax.motor
    return Circuit(r=motor.armature_resistance, l=motor.armature_inductance,
                   k=motor.emf_constant, u_hat=conv.peak_voltage, pulses=conv.pulse_number,
                   mains=conv.mains_frequency, l_c=conv.line_inductance,
                   series=conv.series_phases)


def _open_loop(ax, alpha_deg: float, emf: float, periods: float, dt: float = DT):
    """The forward converter fired at a fixed angle against a rotor held at the speed that
    gives ``emf``; returns (run, drives)."""
    drives = Drives([ax], dt=dt, firing_log=20000)
    drives.set_firing_angle([math.radians(alpha_deg)])
    omega = emf / ax.motor.emf_constant
    run = simulate(drives, 0.0, periods / ax.converter.mains_frequency, inertia=1e12,
                   omega0=omega)
    return run, drives


def _compare(ax, run, drives, dt):
    """Kernel against the reference over the last mains period: (RMS error / RMS current,
    relative error of the mean current)."""
    c = _circuit(ax)
    omega = np.concatenate([[run.omega[0, 0]], run.omega[:-1, 0]])  # speeds at the starts
    t_end = float(run.time[-1])
    ref, q = replay(c, drives.firings()[0], omega, dt, t_end, run.time)
    last = run.time > t_end - 1.0 / c.mains + 1e-12
    kernel = run.current[last, 0]
    rms_err = np.sqrt(np.mean((kernel - ref[last]) ** 2)) / np.sqrt(np.mean(ref[last] ** 2))
    q_kernel = float(np.sum(run.torque[:, 0]) * dt / ax.motor.emf_constant)
    return rms_err, abs(q_kernel - q) / abs(q), kernel


@pytest.mark.parametrize(("alpha", "emf", "continuous"), [
    (60.0, 40.0, True),    # 14 A mean: far above the boundary (3.5 A at 60°)
    (60.0, 64.0, False),   # a few A: discontinuous, starting at the firing
    (95.0, 8.0, False),    # a narrow pulse at low voltage: the feed-speed regime
    (0.0, 139.0, False),   # reverse biased at the firing (122 V < E): conduction starts on
                           # the rising sine, 19° later (long gate pulse)
])
def test_open_loop_current_matches_the_reference(alpha, emf, continuous):
    run, drives = _open_loop(AX, alpha, emf, periods=6)
    rms_err, mean_err, _ = _compare(AX, run, drives, DT)
    assert rms_err < 0.02
    assert mean_err < 0.01
    tail = run.current[run.time > run.time[-1] - 0.02, 0]
    assert (tail.min() > 0.0) == continuous
    assert tail.min() >= 0.0  # a thyristor converter never reverses its current


def test_commutation_overlap_matches_the_reference():
    ax = TOMSK.with_overrides({"axes.y.converter.line_inductance": 0.5e-3}).axes["y"]
    run, drives = _open_loop(ax, 45.0, 30.0, periods=6)
    rms_err, mean_err, _ = _compare(ax, run, drives, DT)
    assert rms_err < 0.02
    assert mean_err < 0.01
    # the overlap costs mean voltage: less current than without the line inductance
    plain, _ = _open_loop(AX, 45.0, 30.0, periods=6)
    tail = run.time > run.time[-1] - 0.02
    assert run.current[tail, 0].mean() < plain.current[tail, 0].mean()


def test_reversal_through_the_closed_loop_matches_the_reference():
    drives = Drives([AX], dt=DT, firing_log=20000)
    run = simulate(drives, lambda t: 2.0 if t < 0.15 else -2.0, 0.3,
                   coulomb=AX.mechanics.rotor_coulomb, viscous=AX.mechanics.rotor_viscous)
    bridges = set(drives.firings()[0][:, 2].tolist())
    assert {1.0, -1.0, 0.0} <= bridges  # both converters fired, pulses removed between
    c = _circuit(AX)
    omega = np.concatenate([[0.0], run.omega[:-1, 0]])
    ref, q = replay(c, drives.firings()[0], omega, DT, float(run.time[-1]), run.time)
    # the reversal window: from the last forward firing to 20 ms of reverse conduction
    log = drives.firings()[0]
    t_rev = log[log[:, 2] == -1.0, 0][0]
    window = (run.time > t_rev - 0.02) & (run.time < t_rev + 0.02)
    err = np.sqrt(np.mean((run.current[window, 0] - ref[window]) ** 2))
    assert err / np.sqrt(np.mean(ref[window] ** 2)) < 0.02
    q_kernel = float(np.sum(run.torque[:, 0]) * DT / AX.motor.emf_constant)
    assert abs(q_kernel - q) <= 0.01 * float(np.sum(np.abs(run.torque[:, 0])) * DT
                                             / AX.motor.emf_constant)
    # the current never changes sign inside one converter's conduction, and is zero in
    # the reversal pause
    assert np.all(run.current[run.bridge[:, 0] == 1, 0] >= 0.0)
    assert np.all(run.current[run.bridge[:, 0] == -1, 0] <= 0.0)


def _conducts_throughout(alpha_deg: float, emf: float) -> tuple[bool, float]:
    """Steady open-loop run: (current never zero over the last period, mean current)."""
    run, _ = _open_loop(AX, alpha_deg, emf, periods=12, dt=T_P / 16)
    last = run.time > run.time[-1] - 1.0 / AX.converter.mains_frequency + 1e-12
    mean = float(np.mean(run.torque[last, 0])) / AX.motor.emf_constant
    return bool(run.current[last, 0].min() > 0.0), mean


@pytest.mark.parametrize("alpha", [30.0, 60.0, 90.0])
def test_boundary_current_matches_the_closed_form(alpha):
    """Bisect the EMF at which conduction becomes continuous; the mean current there is
    the boundary current of the closed form (with R, and R → 0 is the textbook's)."""
    conv, motor = AX.converter, AX.motor
    u_d0 = conv.max_voltage
    lo, hi = u_d0 * math.cos(math.radians(alpha)) - 40.0, u_d0 * math.cos(math.radians(alpha))
    assert _conducts_throughout(alpha, lo)[0] and not _conducts_throughout(alpha, hi)[0]
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        if _conducts_throughout(alpha, mid)[0]:
            lo = mid
        else:
            hi = mid
    i_b = _conducts_throughout(alpha, lo)[1]
    a = 2 * math.pi * conv.mains_frequency * motor.armature_inductance \
        / motor.armature_resistance
    expected = boundary_current(math.radians(alpha), conv.pulse_number, a) \
        * conv.peak_voltage / motor.armature_resistance
    assert i_b == pytest.approx(expected, rel=0.02)
    textbook = (conv.peak_voltage / (2 * math.pi * conv.mains_frequency
                                     * motor.armature_inductance)
                * (1 - math.pi / 6 / math.tan(math.pi / 6)) * math.sin(math.radians(alpha)))
    assert textbook == pytest.approx(4.19 * math.sin(math.radians(alpha)), rel=0.01)
    assert 0.85 * textbook < i_b < textbook  # R > 0 lowers it a little


def test_midpoint_circuit_has_three_pulses_and_its_own_u_d0():
    ax = TOMSK.with_overrides({"axes.y.converter.pulse_number": 3}).axes["y"]
    assert ax.converter.max_voltage == pytest.approx(
        3 / math.pi * math.sin(math.pi / 3) * math.sqrt(2 / 3) * ax.converter.line_voltage)
    run, drives = _open_loop(ax, 30.0, 20.0, periods=6, dt=ax.converter.firing_period / 7.3)
    log = drives.firings()[0]
    assert np.diff(log[-6:, 0]) == pytest.approx([1 / 150] * 5, rel=1e-9)
    rms_err, mean_err, _ = _compare(ax, run, drives, ax.converter.firing_period / 7.3)
    assert rms_err < 0.02 and mean_err < 0.01
