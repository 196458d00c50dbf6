"""Low-current physics of the pulse-level converter (brush and thyristor drops, slope
resistance, latching and holding currents with finite gate pulses, a smoothing reactor, the
mains' deviation, commutation overlap) against the independent solve_ivp circuit of
``thyristor_reference``, over many random operating points in continuous and discontinuous
conduction, 6-pulse bridge and 3-pulse midpoint circuit."""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest

from twin.config import load_machine
from twin.drive import Drives

from .thyristor_reference import Bridge, simulate

TOMSK = load_machine("tomsk_xy")
CASES = 8 if os.environ.get("CI") else 48
PERIODS = 4                          # mains periods simulated


def _random_bridge(rng: np.random.Generator, k: int) -> tuple[Bridge, float, float]:
    """A random circuit and operating point (α, E); even k aim at continuous conduction,
    odd k at discontinuous (the reference decides which it is)."""
    pulses = 6 if rng.random() < 0.7 else 3
    gate = 0.0 if rng.random() < 0.4 else float(rng.uniform(0.2e-3, 1.5e-3))
    i_l = float(rng.uniform(0.02, 0.5)) if gate > 0.0 or rng.random() < 0.5 else 0.0
    c = Bridge(r=float(rng.uniform(0.5, 5.0)), l=float(rng.uniform(2e-3, 40e-3)),
               u_ll=float(rng.uniform(60.0, 220.0)), pulses=pulses,
               deviation=float(rng.uniform(-0.1, 0.1)),
               l_s=0.0 if rng.random() < 0.5 else float(rng.uniform(1e-3, 50e-3)),
               l_c=0.0 if rng.random() < 0.6 else float(rng.uniform(0.05e-3, 0.8e-3)),
               brush=float(rng.uniform(0.0, 2.0)), v_t0=float(rng.uniform(0.0, 1.5)),
               r_t=0.0 if rng.random() < 0.3 else float(rng.uniform(0.005, 0.08)),
               i_l=i_l, i_h=float(rng.uniform(0.0, 1.0)) * i_l, gate=gate)
    alpha = math.radians(float(rng.uniform(15.0, 120.0)))
    l_tot = c.l + c.l_s + c.n * c.l_c
    u_mean = c.pulses / math.pi * math.sin(math.pi / c.pulses) * c.u_hat * math.cos(alpha)
    i_b = (c.u_hat / (c.w * l_tot) * (1 - math.pi / c.pulses / math.tan(math.pi / c.pulses))
           * math.sin(alpha))
    share = rng.uniform(1.5, 3.0) if k % 2 == 0 else rng.uniform(0.03, 0.6)
    emf = u_mean - c.drop - (c.r + c.n * c.r_t) * share * i_b
    return c, alpha, emf


def _kernel(c: Bridge, alpha: float, emf: float, dt: float, steps: int):
    """The twin's drive with the same circuit, fired open loop at α against a rotor held
    at the speed of ``emf``: the current at the end of each interval and ∫i dt."""
    cfg = TOMSK.with_overrides({
        "axes.y.motor.armature_resistance": c.r, "axes.y.motor.armature_inductance": c.l,
        "axes.y.motor.brush_drop": c.brush,
        "axes.y.converter.line_voltage": c.u_ll, "axes.y.converter.pulse_number": c.pulses,
        "axes.y.converter.mains_deviation": c.deviation,
        "axes.y.converter.smoothing_inductance": c.l_s,
        "axes.y.converter.line_inductance": c.l_c,
        "axes.y.converter.thyristor_threshold": c.v_t0,
        "axes.y.converter.thyristor_resistance": c.r_t,
        "axes.y.converter.latching_current": c.i_l,
        "axes.y.converter.holding_current": c.i_h,
        "axes.y.converter.gate_pulse_width": c.gate})
    ax = cfg.axes["y"]
    drives = Drives([ax], dt=dt)
    drives.set_firing_angle([alpha])
    omega = np.array([emf / ax.motor.emf_constant])
    current, charge = np.empty(steps), 0.0
    for n in range(steps):
        charge += float(drives.step(np.zeros(1), omega)[0]) * dt / ax.motor.emf_constant
        current[n] = drives.current[0]
    return current, charge


def test_the_converter_with_its_drops_matches_the_reference_circuit():
    rng = np.random.default_rng(2029)
    modes = set()
    worst = 0.0
    decided = 0           # cases where latching or holding changed the waveform
    for k in range(CASES):
        c, alpha, emf = _random_bridge(rng, k)
        dt = c.t_p / 13.7        # intervals not commensurate with the pulses
        steps = round(PERIODS / c.mains / dt)
        times = dt * np.arange(1, steps + 1)
        kernel, q_kernel = _kernel(c, alpha, emf, dt, steps)
        ref, q_ref = simulate(c, alpha, emf, float(times[-1]), times)
        peak = float(np.max(np.abs(ref)))
        assert peak > 0.0, (k, c, alpha, emf)
        err = float(np.sqrt(np.mean((kernel - ref) ** 2))) / peak
        worst = max(worst, err)
        last = times > times[-1] - 1.0 / c.mains
        modes.add("continuous" if ref[last].min() > 0.0 else "discontinuous")
        assert err <= 1e-3, (k, err, c, math.degrees(alpha), emf)
        assert q_kernel == pytest.approx(q_ref, rel=1e-4, abs=1e-6 * peak * times[-1])
        assert kernel.min() >= 0.0   # a thyristor converter never reverses its current
        if c.i_l > 0.0:
            plain, _ = simulate(dataclasses.replace(c, i_l=0.0, i_h=0.0), alpha, emf,
                                float(times[-1]), times)
            decided += bool(np.abs(plain - ref).max() > 1e-2 * peak)
    print(f"{CASES} random circuits: worst RMS error {worst:.2e} of the peak; latching or "
          f"holding decided {decided}")
    assert modes == {"continuous", "discontinuous"}
    assert decided >= 1


def test_each_drop_lowers_the_current_as_the_circuit_says():
    """Mean current at a fixed angle in continuous conduction: (U_d0·cos α − U_v − E)/R_eff
    less the commutation's voltage loss; with the drops the kernel's mean falls by U_v/R_eff
    and the mains deviation raises U_d0 by δ (analytic)."""
    base = Bridge(r=2.0, l=40e-3, u_ll=100.0)
    alpha, emf = math.radians(50.0), 40.0
    dt = base.t_p / 10
    steps = round(12 / base.mains / dt)
    last = slice(steps - round(1 / base.mains / dt), steps)

    def mean(c: Bridge) -> float:
        current, _ = _kernel(c, alpha, emf, dt, steps)
        return float(np.mean(current[last]))

    u_d0 = 3 / math.pi * math.sqrt(2) * 100.0
    plain = mean(base)
    assert plain == pytest.approx((u_d0 * math.cos(alpha) - emf) / 2.0, rel=2e-3)
    drops = Bridge(r=2.0, l=40e-3, u_ll=100.0, brush=1.5, v_t0=1.0, r_t=0.05)
    assert mean(drops) == pytest.approx(
        (u_d0 * math.cos(alpha) - emf - 1.5 - 2 * 1.0) / (2.0 + 2 * 0.05), rel=2e-3)
    low = Bridge(r=2.0, l=40e-3, u_ll=100.0, deviation=-0.1)
    assert mean(low) == pytest.approx((0.9 * u_d0 * math.cos(alpha) - emf) / 2.0, rel=2e-3)


def test_a_short_gate_pulse_that_does_not_latch_cuts_the_pulse():
    """A narrow current pulse that cannot reach the latching current within a short gate
    pulse is cut at the pulse's end; with long pulses (0) the same circuit conducts the
    whole pulse (gate-assisted), and the holding current ends a latched pulse early."""
    alpha, emf = math.radians(100.0), 20.0   # pulses of 0.9 A, 1.2 ms long
    common = dict(r=2.0, l=10e-3, u_ll=100.0)
    dt = Bridge(**common).t_p / 40
    steps = round(3 / 50.0 / dt)
    long_, q_long = _kernel(Bridge(**common, i_l=0.3, i_h=0.1), alpha, emf, dt, steps)
    cut, q_cut = _kernel(Bridge(**common, i_l=5.0, i_h=0.1, gate=0.3e-3), alpha, emf, dt,
                         steps)
    held, q_held = _kernel(Bridge(**common, i_l=0.3, i_h=0.3, gate=0.3e-3), alpha, emf, dt,
                           steps)
    assert long_.max() > 0.5
    assert 0.0 < q_cut < 0.3 * q_long     # cut 0.3 ms after each firing
    assert cut.max() < 0.8 * long_.max()  # before the pulse's crest
    assert held.max() == pytest.approx(long_.max(), rel=1e-9)  # the same rise
    assert 0.5 * q_long < q_held < q_long  # latched, ends at 0.3 A instead of 0
