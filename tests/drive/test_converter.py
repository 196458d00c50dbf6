"""Converters: the mean-value thyristor bridge pair (firing grid, arccos law, limits,
discontinuous current, reversal pause) and PWM (hold over the PWM period, saturation, free
current reversal). The pulse-level model, the thyristor default, is tested against its own
reference in ``test_pulse_converter.py``; tests here that hold for both run both."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.drive import Drives

from .rig import simulate

TOMSK_PULSE = load_machine("tomsk_xy")
TOMSK = TOMSK_PULSE.with_overrides({"axes.*.converter.model": "mean"})
LASER = load_machine("laser_belt")
SUB = 8  # drive updates per firing period in the grid tests


def _reversal(t: float) -> float:
    return 0.5 if t < 0.1 else -0.5


def _change_steps(values: np.ndarray) -> np.ndarray:
    """Indices n where values[n] differs from values[n − 1] (NaN-aware)."""
    a, b = values[1:], values[:-1]
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    return np.nonzero(~same)[0] + 1


@pytest.mark.parametrize("cfg", [TOMSK, LASER], ids=["thyristor", "pwm"])
def test_voltage_is_held_between_firing_instants(cfg):
    ax = cfg.axes["y"]
    t_p = ax.converter.firing_period
    drives = Drives([ax], dt=t_p / SUB)
    duration = 0.2 if ax.converter.kind == "thyristor" else 0.02
    run = simulate(drives, lambda t: 0.3 if t < duration / 2 else -0.3, duration,
                   coulomb=ax.mechanics.rotor_coulomb, viscous=ax.mechanics.rotor_viscous)
    v = run.voltage[:, 0]
    changes = _change_steps(v)
    assert changes.size > 10
    # update n covers [n·dt, (n+1)·dt]; a firing instant j·T_p starts update n = SUB·j
    assert np.all((changes - 1) % SUB == SUB - 1)
    if ax.converter.kind == "thyristor":
        assert t_p == pytest.approx(1.0 / 300.0)  # 6 pulses per 50 Hz period
        spacing = np.diff(changes) * drives.dt
        assert spacing.min() == pytest.approx(t_p)


def test_voltage_responds_at_the_next_firing_instant_only():
    """The converter delay: a reference step between firing instants acts at the next one."""
    for cfg, step_at in [(TOMSK, 10.5), (LASER, 10.25)]:
        ax = cfg.axes["y"]
        t_p = ax.converter.firing_period
        drives = Drives([ax], dt=t_p / SUB)
        t_step = step_at * t_p
        run = simulate(drives, lambda t, t_step=t_step: 0.0 if t < t_step - 1e-12 else 1.0,
                       12 * t_p, load=0.2)
        v = run.voltage[:, 0]
        first = _change_steps(v)
        first = first[run.time[first] > t_step + 1e-12][0]
        # record n holds the value fired at the start of update n, i.e. at time n·dt
        assert (first * drives.dt) == pytest.approx(math.ceil(step_at) * t_p)


def test_arccos_firing_law_and_angle_limits():
    ax = TOMSK.axes["y"]
    conv = ax.converter
    u_d0 = 3 * math.sqrt(2) / math.pi * conv.line_voltage
    drives = Drives([ax], dt=1e-3)
    run = simulate(drives, lambda t: 3.0 if t < 0.15 else -3.0, 0.3, coulomb=0.03)
    conducting = run.bridge[:, 0] != 0
    v, b, alpha = run.voltage[conducting, 0], run.bridge[conducting, 0], run.firing_angle[
        conducting, 0]
    np.testing.assert_allclose(v, b * u_d0 * np.cos(alpha), atol=1e-9)
    assert np.all(alpha >= conv.min_firing_angle - 1e-12)
    assert np.all(alpha <= conv.max_firing_angle + 1e-12)
    assert np.all(np.isnan(run.firing_angle[~conducting, 0]))


@pytest.mark.parametrize("model", ["mean", "pulse"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_thyristor_saturates_at_the_firing_angle_limits(sign, model):
    """Rotor driven beyond the converter's reach (EMF 147 V > U_d0 = 135 V) and a reference
    above its speed: full rectifier at α_min and no current; then a braking reference: the
    other bridge at the inverter end stop α_max, unable to hold the current. The reference
    filter is off so that the reference acts at once."""
    cfg = TOMSK.with_overrides({"axes.y.speed_loop.reference_filter": 0.0,
                                "axes.y.converter.model": model})
    ax = cfg.axes["y"]
    conv = ax.converter
    u_d0 = 1.3505 * conv.line_voltage
    drives = Drives([ax], dt=1e-3)
    omega = np.array([sign * 300.0])  # tacho 14.3 V
    for _ in range(60):
        drives.step(np.array([sign * 15.0]), omega)
    assert drives.bridge[0] == sign
    assert drives.firing_angle[0] == pytest.approx(conv.min_firing_angle)
    assert drives.voltage[0] == pytest.approx(sign * u_d0, rel=1e-4)
    assert drives.current[0] == 0.0  # the bridge cannot push current against a higher EMF
    for _ in range(60):
        drives.step(np.array([-sign * 10.0]), omega)
    assert drives.bridge[0] == -sign
    assert drives.firing_angle[0] == pytest.approx(conv.max_firing_angle)
    assert drives.voltage[0] == pytest.approx(-sign * u_d0 * math.cos(conv.max_firing_angle),
                                              rel=1e-4)
    assert drives.current[0] * sign < 0.0


@pytest.mark.parametrize("cfg", [TOMSK, TOMSK_PULSE], ids=["mean", "pulse"])
def test_current_never_changes_sign_while_a_bridge_conducts(cfg):
    ax = cfg.axes["y"]
    drives = Drives([ax], dt=1e-4)
    run = simulate(drives, lambda t: 1.0 * math.sin(2 * math.pi * 3.0 * t), 0.7,
                   coulomb=ax.mechanics.rotor_coulomb, viscous=ax.mechanics.rotor_viscous)
    i, b = run.current[:, 0], run.bridge[:, 0]
    assert np.all(i * b >= 0.0)
    assert np.all(i[b == 0] == 0.0)
    assert {-1, 0, 1} <= set(np.unique(b))  # it did reverse, through the blocked state


@pytest.mark.parametrize("model", ["mean", "pulse"])
@pytest.mark.parametrize("pause", [None, 8e-3])
def test_reversal_pause_is_honoured(pause, model):
    cfg = TOMSK.with_overrides({"axes.y.converter.model": model})
    if pause is not None:
        cfg = cfg.with_overrides({"axes.y.converter.reversal_pause": pause})
    ax = cfg.axes["y"]
    pause = ax.converter.reversal_pause
    drives = Drives([ax], dt=ax.converter.firing_period / SUB)
    run = simulate(drives, _reversal, 0.2, coulomb=ax.mechanics.rotor_coulomb,
                   viscous=ax.mechanics.rotor_viscous)
    i, b, t = run.current[:, 0], run.bridge[:, 0], run.time
    k_reverse = np.nonzero((i < 0.0) & (t > 0.1))[0][0]
    k_forward = np.nonzero(i[:k_reverse] > 0.0)[0][-1]
    k_blocked = np.nonzero(b[:k_reverse] != 0)[0][-1] + 1  # first update of the last pause
    zero_time = t[k_reverse - 1] - t[k_forward]  # current exactly 0 at both ends, at least
    blocked_time = (k_reverse - k_blocked) * drives.dt
    print(f"reversal: zero current for {zero_time * 1e3:.2f} ms, pulses removed "
          f"{blocked_time * 1e3:.2f} ms (pause {pause * 1e3:.1f} ms)")
    assert np.all(b[k_forward + 1:k_reverse] >= 0) and np.all(i[k_forward + 1:k_reverse] == 0)
    assert zero_time >= pause
    assert blocked_time >= pause - drives.dt
    if model == "mean":
        t_p = ax.converter.firing_period
        release = k_reverse * drives.dt  # the reverse bridge fires on the firing grid
        assert release / t_p == pytest.approx(round(release / t_p), abs=1e-6)


@pytest.mark.parametrize(("load", "discontinuous"), [(0.0, True), (0.98, False)])
def test_discontinuous_current_at_light_load_and_low_speed(load, discontinuous):
    """Low-speed regulation (0.2 → 0.15 → 0.2 V, ≈ 40 rpm), preset friction, with and
    without a load torque of half the rated torque.

    Light load: slowing down needs less than zero current, which a conducting bridge cannot
    give; its current stops and stays zero for whole firing periods while the bridge is
    still selected (discontinuous conduction), before the logic reverses. Loaded: the
    demand stays positive and the current continuous.
    """
    ax = TOMSK.axes["y"]
    drives = Drives([ax], dt=ax.converter.firing_period / SUB)
    run = simulate(drives, lambda t: 0.15 if 0.2 <= t < 0.4 else 0.2, 0.6, load=load,
                   coulomb=ax.mechanics.rotor_coulomb, viscous=ax.mechanics.rotor_viscous)
    late = run.time > 0.15
    i, b = run.current[late, 0], run.bridge[late, 0]
    gaps = (i == 0.0) & (b != 0)
    extinctions = np.count_nonzero(gaps[1:] & (i[:-1] != 0.0) & (b[1:] == b[:-1]))
    print(f"load {load} N·m: {extinctions} extinctions, zero current with a bridge selected "
          f"{gaps.mean():.2%} of the time")
    if discontinuous:
        assert extinctions >= 2  # once slowing down, once speeding up again
    else:
        assert not gaps.any()
        assert np.all(i > 0.0) and np.all(b == 1)


def test_pwm_saturates_at_the_dc_link_and_current_reverses_freely():
    ax = LASER.axes["y"]
    u_dc = ax.converter.dc_link_voltage
    drives = Drives([ax], dt=1e-4)
    omega = np.array([500.0])  # EMF 125 V above the 110 V link
    for _ in range(50):
        drives.step(np.array([10.0]), omega)
    assert drives.voltage[0] == pytest.approx(u_dc)
    assert drives.current[0] < 0.0  # regenerating through the same bridge
    assert drives.bridge[0] == 1
    assert np.isnan(drives.firing_angle[0])
    run = simulate(Drives([ax], dt=1e-4), lambda t: 0.2 if t < 0.05 else -0.2, 0.1, load=0.0)
    i = run.current[:, 0]
    crossings = np.nonzero((i[1:] < 0.0) & (i[:-1] > 0.0))[0]
    assert crossings.size and np.all(run.bridge[:, 0] == 1)
    assert np.all(np.abs(run.voltage[:, 0]) <= u_dc)
