"""Residual vibration (``twin.analysis.vibration``) on synthetic records whose free
vibration is known in closed form: random modes, pulses, settled values and tick rates."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.analysis.vibration import MIN_PERIODS, quiet_intervals, residual_vibration


def _record(rng, f, z):
    """Ticks with acceleration pulses on both axes and a deflection that, once each pulse
    ends, rings down from a random amplitude about a random settled value; returns the
    record and the largest amplitude over the intervals long enough to be judged."""
    period, dt = float(rng.uniform(1e-3, 4e-3)), float(rng.uniform(1e-4, 3e-4))
    w, mode = 2 * math.pi * f, 1.0 / f
    wd = w * math.sqrt(1 - z * z)
    t_end = 30 * mode
    t = np.arange(0.0, t_end, period)
    ft = np.arange(0.0, t_end, dt)
    acc, d = np.zeros((t.size, 2)), np.zeros((ft.size, 2))
    expect = 0.0
    for k in range(2):
        edge = 0.0
        while edge < t_end - 4 * mode:
            pulse = float(rng.uniform(0.2, 1.0)) * mode
            quiet = float(rng.uniform(0.5, 4.0)) * mode
            a0, a1 = edge, edge + pulse
            amp, settled = rng.uniform(-50e-6, 50e-6, 2)
            acc[(t >= a0) & (t < a1), k] = float(rng.uniform(0.1, 2.0))
            on = (ft >= a0) & (ft < a1)
            d[on, k] = settled + 3 * abs(amp) + 1e-5          # bigger while it accelerates
            tau = ft - a1
            free = (ft >= a1) & (ft < a1 + quiet)
            d[free, k] = settled + amp * np.exp(-z * w * tau[free]) * np.cos(wd * tau[free])
            q = t[(t >= a1) & (t < a1 + quiet)]
            if q.size and q[-1] - q[0] >= MIN_PERIODS * mode:
                # the ring-down from the interval's first tick, densely (closed form)
                tau = np.linspace(q[0] - a1, q[-1] - a1 - 0.5 * mode, 20001)
                ring = np.abs(amp * np.exp(-z * w * tau) * np.cos(wd * tau))
                expect = max(expect, float(ring.max()))
            edge = a1 + quiet
        d[ft >= edge, k] = d[np.searchsorted(ft, edge) - 1, k]
        acc[t >= edge, k] = 1.0                               # busy until the end
    return t, acc, ft, d, (mode, mode), expect


@pytest.mark.parametrize("seed", range(12))
def test_the_free_vibration_after_each_pulse_is_found(seed):
    rng = np.random.default_rng(seed)
    f, z = float(rng.uniform(5.0, 60.0)), float(rng.uniform(0.1, 0.5))
    t, acc, ft, d, periods, expect = _record(rng, f, z)
    got = residual_vibration(t, acc, ft, d, periods)
    # the settled value is the mean of a ring-down over half a period (≥ 1 period in):
    # off by at most the envelope there, e^(−2πζ)·amp; the samples miss a peak by at most
    # ω·dt·amp
    assert expect > 0
    slack = math.exp(-2 * math.pi * z) * 50e-6 + 2 * math.pi * f * 3e-4 * 50e-6
    assert abs(got - expect) <= slack


def test_no_quiet_interval_long_enough_is_no_vibration():
    t = np.arange(0.0, 1.0, 1e-3)
    acc = np.ones((t.size, 2))
    acc[500:520] = 0.0                       # 20 ms quiet: shorter than 1.5 periods of 20 Hz
    assert residual_vibration(t, acc, t, np.random.default_rng(0).normal(size=(t.size, 2)),
                              (0.05, 0.05)) == 0.0
    assert quiet_intervals(t, acc[:, 0], 0.019) == [(t[500], t[519])]
