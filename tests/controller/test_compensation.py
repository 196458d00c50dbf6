"""Reference compensations (``twin.controller.compensation``) against analytic references:
a shaped circle's radius (exact for a sampled circle, and its fourth-order term), the
closed loop's second moment of a continuous servo, and a belt-driven mass with Coulomb
friction integrated by scipy, on machines whose truth differs from the belief by ±30 %."""

from __future__ import annotations

import functools
import math
import os

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from twin.config import load_machine
from twin.controller.compensation import (
    ReferenceCompensation,
    compensated_circle_error,
    compensation_table,
    curvature_step_error,
    loop_variance,
    smoothing_quartic,
)
from twin.controller.gains import RegulatorGains
from twin.controller.linear import LinearAxisModel
from twin.controller.shaping import SHAPERS, ReferenceShaper, circle_error, design

CI = bool(os.environ.get("CI"))
PERIOD = 3.5e-3


class _Settings:
    def __init__(self, smoothing=False, stretch=False, band=2e-3):
        self.smoothing, self.stretch, self.reversal_band = smoothing, stretch, band


def _circle_through(shaper, radius, speed, compensate):
    """A sampled circle (analytic p, v, a, j) through the compensation and the shaper;
    the output's radius once the shaper's history is all on the circle (m)."""
    axes = load_machine("laser_belt").axes
    par = compensation_table(_Settings(smoothing=compensate), axes, (shaper, shaper),
                             (0.0, 0.0), PERIOD)
    comp = ReferenceCompensation(par, PERIOD) if compensate else None
    sh = ReferenceShaper((shaper, shaper), PERIOD)
    w = speed / radius
    n = int(sh.index.max()) + 40
    sh.reset((radius, 0.0))
    out = []
    for k in range(n):
        th = w * k * PERIOD
        c, s = math.cos(th), math.sin(th)
        p = np.array([radius * c, radius * s])
        v = np.array([-speed * s, speed * c])
        a = -w * w * p
        j = -w * w * v
        if comp is not None:
            comp.apply(0, p, v, a, j)
        sh.apply(p, v, a, j)
        if comp is not None:
            comp.apply(1, p, v, a, j)
        out.append(math.hypot(*p))
    return np.array(out[-20:])


def _cases(n, seed):
    rng = np.random.default_rng(seed)
    return [(str(rng.choice(SHAPERS)), float(rng.uniform(8.0, 40.0)),
             float(rng.uniform(0.0, 0.5)), float(rng.uniform(2e-3, 30e-3)),
             float(rng.uniform(0.01, 0.06))) for _ in range(n)]


@pytest.mark.parametrize(("name", "f", "z", "radius", "speed"), _cases(4 if CI else 16, 31))
def test_a_compensated_shaped_circle_keeps_its_radius(name, f, z, radius, speed):
    """Sampled exactly, the FIR turns a circle into one of radius R·|H_d(Ω)|, and the
    compensation multiplies the input's radius by 1 + Ω²σ_d²/2 (σ_d of the taps): exact.
    The error left is the fourth-order R·g4·Ω⁴, far below the uncompensated a·σ²/2."""
    shaper = design(name, f, z)
    taps = shaper.discrete(PERIOD)
    got = _circle_through(shaper, radius, speed, True)
    assert np.ptp(got) < 1e-12
    assert got[-1] == pytest.approx(radius - compensated_circle_error(taps, radius, speed),
                                    rel=0, abs=1e-12)
    plain = _circle_through(shaper, radius, speed, False)[-1]
    assert plain == pytest.approx(radius - circle_error(taps, radius, speed), abs=1e-12)
    w = speed / radius
    shrink, left = radius - plain, radius - got[-1]
    assert shrink == pytest.approx(0.5 * speed * w * taps.spread**2, rel=0.2)
    if (w * taps.spread) < 0.3:
        assert left == pytest.approx(radius * smoothing_quartic(taps) * w**4,
                                     rel=0.35, abs=1e-9)
    assert abs(left) < 0.25 * shrink


@pytest.mark.parametrize("seed", range(2 if CI else 8))
def test_the_loop_variance_of_a_fast_sampled_servo(seed):
    """K_H/(p(Tp + 1)) under P control K_v = kp·K_H, sampled fast: the closed loop
    1/(1 + s/K_v + T·s²/K_v) has m1 = 1/K_v and σ² = 1/K_v² − 2T/K_v."""
    rng = np.random.default_rng(seed)
    kh, t, kv = rng.uniform(0.01, 0.1), rng.uniform(1e-3, 5e-3), rng.uniform(10.0, 60.0)
    model = LinearAxisModel.servo(kh, t)
    gains = RegulatorGains(kp=kv / kh)
    got = loop_variance(model, gains, 1e-6, 0)
    assert got == pytest.approx(1.0 / kv**2 - 2.0 * t / kv, rel=2e-3)


@functools.cache
def _belt_run(scale_k, scale_f, compensate, seed):
    """An axis of laser_belt (y): the motor follows the reference exactly, the belt (k, c)
    pulls the table against viscous and Coulomb friction (smoothed over 0.2 mm/s), on a
    sine of 2 mm at 1.5 Hz: two reversals. The truth is the belief scaled; the largest
    table error after the first reversal (m)."""
    cfg = load_machine("laser_belt")
    axes = cfg.axes
    par = compensation_table(_Settings(stretch=True), axes, (None, None), (0.0, 0.0),
                             PERIOD)
    mech, tr = axes["y"].mechanics, axes["y"].transmission
    m = mech.carriage_mass
    k = tr.axial_stiffness * scale_k
    c = 2.0 * tr.damping_ratio * math.sqrt(k * m)
    fc, b = mech.slide_coulomb * scale_f, mech.slide_viscous * scale_f
    amp, w = 2e-3, 2.0 * math.pi * 1.5 * (1.0 + 0.1 * seed)
    comp = ReferenceCompensation(par, PERIOD)
    ticks = int(1.2 / PERIOD)
    motor = np.zeros(ticks)
    ref = np.zeros(ticks)
    for i in range(ticks):
        t = i * PERIOD
        p = np.array([0.0, amp * math.sin(w * t)])
        v = np.array([0.0, amp * w * math.cos(w * t)])
        a = np.array([0.0, -amp * w * w * math.sin(w * t)])
        ref[i] = p[1]
        if compensate:
            comp.apply(0, p, v, a, np.zeros(2))
            comp.apply(1, p, v, a, np.zeros(2))
        motor[i] = p[1]

    def rhs(t, y):
        xm = np.interp(t, np.arange(ticks) * PERIOD, motor)
        vm = amp * w * math.cos(w * t)
        x, v = y
        f = k * (xm - x) + c * (vm - v) - b * v - fc * math.tanh(v / 2e-4)
        return [v, f / m]

    t_eval = np.arange(ticks) * PERIOD
    y0 = [motor[0], amp * w]
    sol = solve_ivp(rhs, (0.0, t_eval[-1]), y0, t_eval=t_eval, max_step=2e-4, rtol=1e-8,
                    atol=1e-11)
    err = np.abs(sol.y[0] - ref)
    return float(err[int(0.4 / PERIOD):].max())


@pytest.mark.parametrize(("scale_k", "scale_f"), [(0.7, 1.3), (1.3, 0.7)]
                         if CI else [(s, f) for s in (0.7, 1.0, 1.3) for f in (0.7, 1.0, 1.3)
                                     if (s, f) != (1.0, 1.0)])
def test_the_stretch_compensation_helps_on_a_perturbed_belt(scale_k, scale_f):
    """From the belief's nominal m, k, b, F_c only. On the nominal machine the reversal
    error drops to what the compensation leaves by design (the stretch m·a/k along the
    motion, and the band over which the offset flips); with the truth off by ±30 % it still
    helps, and it never hurts beyond that residual (scaled with the true stretch) plus what
    the mismatch itself predicts: 2·|ΔD| across a reversal, |Δβ|·v and m·a·|Δ(1/k)|."""
    nominal_plain = _belt_run(1.0, 1.0, False, 0)
    nominal = _belt_run(1.0, 1.0, True, 0)
    axes = load_machine("laser_belt").axes
    mech, tr = axes["y"].mechanics, axes["y"].transmission
    k = tr.axial_stiffness
    m = mech.carriage_mass
    amp, w = 2e-3, 2.0 * math.pi * 1.5
    stretch = m * amp * w * w / k
    assert nominal < 0.4 * nominal_plain
    assert nominal <= stretch + mech.slide_coulomb / k        # the stretch and the band
    plain = _belt_run(scale_k, scale_f, False, 0)
    comp = _belt_run(scale_k, scale_f, True, 0)
    assert comp < plain
    mismatch = (2.0 * mech.slide_coulomb / k * abs(scale_f / scale_k - 1.0)
                + mech.slide_viscous / k * abs(scale_f / scale_k - 1.0) * amp * w
                + stretch * abs(1.0 / scale_k - 1.0))
    # the residual scales with the true machine's stretch (1/k, F_c/k)
    assert comp <= nominal * max(1.0, 1.0 / scale_k, scale_f / scale_k) + mismatch


@pytest.mark.parametrize(("name", "f", "z", "radius", "speed"), _cases(3 if CI else 10, 37))
def test_the_transient_where_a_line_meets_an_arc(name, f, z, radius, speed):
    """A line run into a tangent arc at constant speed, sampled, through the compensation
    and the shaper: the largest distance of the output from the path (brute force over the
    path's geometry) is ``curvature_step_error``·a_n of the taps, to first order in the
    small angle the shaper's window sweeps (radius ≥ 50× the window's length)."""
    shaper = design(name, f, z)
    taps = shaper.discrete(PERIOD)
    radius = max(radius * 20.0, 60.0 * speed * taps.duration)
    axes = load_machine("laser_belt").axes
    par = compensation_table(_Settings(smoothing=True), axes, (shaper, shaper), (0.0, 0.0),
                             PERIOD)
    comp = ReferenceCompensation(par, PERIOD)
    sh = ReferenceShaper((shaper, shaper), PERIOD)
    lead = int(sh.index.max()) + 5
    sh.reset((-lead * PERIOD * speed, 0.0))
    a_n = speed * speed / radius
    worst = 0.0
    for k in range(-lead, 3 * lead):
        t = k * PERIOD
        if t < 0.0:
            p, v = np.array([speed * t, 0.0]), np.array([speed, 0.0])
            a = np.zeros(2)
        else:
            th = speed * t / radius
            p = np.array([radius * math.sin(th), radius * (1.0 - math.cos(th))])
            v = speed * np.array([math.cos(th), math.sin(th)])
            a = a_n * np.array([-math.sin(th), math.cos(th)])
        comp.apply(0, p, v, a, np.zeros(2))
        sh.apply(p, v, a, np.zeros(2))
        if k >= 0:
            x, y = p
            on_line = abs(y) if x <= 0.0 else math.hypot(x, y)
            on_arc = abs(math.hypot(x, y - radius) - radius) if x >= 0.0 else math.inf
            worst = max(worst, min(on_line, on_arc))
    expect = curvature_step_error(taps) * a_n
    assert worst == pytest.approx(expect, rel=0.01)
    assert curvature_step_error(taps) < curvature_step_error(taps, compensated=False)
