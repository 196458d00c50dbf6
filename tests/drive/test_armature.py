"""Exact armature segments and filters against scipy's adaptive integrator (with events)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from twin.drive.armature import armature_segment, first_order

R, L = 2.0, 10e-3
TA = L / R


def reference_segment(i0, u, e0, e1, h, direction):
    """L·di/dt = u − e0 − e1·t − R·i with a unidirectional converter, by DOP853 + events.

    State (i, q) with q = ∫i dt. A non-conducting bridge waits until its driving voltage
    direction·(u − E(t)) turns positive; a conducting one stops where i crosses zero.
    """
    s = 1.0 if direction >= 0 else -1.0

    def rhs(t, y):
        return [(u - e0 - e1 * t - R * y[0]) / L, y[0]]

    def extinction(t, y):
        return y[0]
    extinction.terminal = True
    extinction.direction = -s  # leaving the conducting sense only

    t_start, i = 0.0, i0
    if direction != 0 and s * i0 <= 0.0:
        i = 0.0
        if s * (u - e0) <= 0.0:
            if s * (u - e0 - e1 * h) <= 0.0:
                return 0.0, 0.0
            t_start = (u - e0) / e1
    sol = solve_ivp(rhs, (t_start, h), [i, 0.0], method="DOP853", rtol=1e-12, atol=1e-15,
                    events=extinction if direction != 0 else None)
    if direction != 0 and sol.status == 1:
        return 0.0, sol.y[1, -1]
    return sol.y[0, -1], sol.y[1, -1]


# i0 (A), u (V), E0 (V), dE/dt (V/s), h (s), direction
CASES = [
    (1.0, 50.0, 20.0, 0.0, 3.3e-3, 1.0),      # continuous, rising
    (3.0, 10.0, 20.0, 0.0, 3.3e-3, 1.0),      # decays to zero inside: extinction
    (3.0, 10.0, 20.0, 0.0, 3.3e-3, 0.0),      # PWM: same, but reverses
    (0.5, 15.0, 20.0, 0.0, 1e-3, 1.0),        # extinction early
    (0.0, 15.0, 20.0, 0.0, 3.3e-3, 1.0),      # stays blocked: u < E
    (0.0, 25.0, 20.0, 0.0, 3.3e-3, 1.0),      # starts from zero
    (0.0, 25.0, 20.0, 3000.0, 3.3e-3, 1.0),   # starts, then the rising EMF extinguishes it
    (0.0, 15.0, 20.0, -3000.0, 3.3e-3, 1.0),  # falling EMF: conduction starts mid-segment
    (2.0, 30.0, 28.0, 2000.0, 3.3e-3, 1.0),   # convex/concave with a ramp: extinction
    (2.0, 30.0, 20.0, 900.0, 3.3e-3, 1.0),    # dips but stays positive
    (-1.0, -50.0, -20.0, 0.0, 3.3e-3, -1.0),  # reverse bridge, continuous
    (-3.0, -10.0, -20.0, 0.0, 3.3e-3, -1.0),  # reverse bridge, extinction
    (0.0, -25.0, -20.0, -3000.0, 3.3e-3, -1.0),  # reverse: start then extinction
    (0.4, -30.0, 10.0, 500.0, 1e-4, 0.0),     # PWM through zero in a short period
    (1.0, 50.0, 20.0, 0.0, 0.0, 1.0),         # zero length
]


@pytest.mark.parametrize(("i0", "u", "e0", "e1", "h", "direction"), CASES)
def test_segment_matches_adaptive_integration(i0, u, e0, e1, h, direction):
    i1, q = armature_segment(i0, u, e0, e1, R, TA, h, direction)
    i_ref, q_ref = (i0, 0.0) if h == 0.0 else reference_segment(i0, u, e0, e1, h, direction)
    assert i1 == pytest.approx(i_ref, abs=1e-9)
    assert q == pytest.approx(q_ref, abs=1e-11)


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_extinguished_current_is_exactly_zero_and_never_reverses(direction):
    s = direction
    i1, _ = armature_segment(s * 3.0, s * 10.0, s * 20.0, 0.0, R, TA, 3.3e-3, direction)
    assert i1 == 0.0
    for h in np.linspace(0.0, 5e-3, 51):
        i, _ = armature_segment(s * 1.0, s * 5.0, s * 30.0, s * 500.0, R, TA, h, direction)
        assert s * i >= 0.0


def test_extinction_instant_closed_form():
    # constant E: i(t) = i∞ + (i0 − i∞)·e^{−t/T_a}, zero at T_a·ln((i0 − i∞)/(−i∞))
    i0, u, e = 3.0, 10.0, 20.0
    i_inf = (u - e) / R
    t_z = TA * math.log((i0 - i_inf) / -i_inf)
    before, q_before = armature_segment(i0, u, e, 0.0, R, TA, t_z * (1 - 1e-9), 1.0)
    after, q_after = armature_segment(i0, u, e, 0.0, R, TA, t_z * (1 + 1e-9), 1.0)
    assert 0.0 < before < 1e-7
    assert after == 0.0
    # charge balance L·i0 + (u − E)·t_z = R·q
    assert q_after == pytest.approx((L * i0 + (u - e) * t_z) / R, rel=1e-9)
    assert q_before == pytest.approx(q_after, rel=1e-6)


@pytest.mark.parametrize(("y0", "x0", "slope", "h", "tau"), [
    (0.0, 1.0, 0.0, 1e-3, 17e-3),
    (0.3, -1.0, 250.0, 3e-3, 1e-3),
    (1.0, 2.0, -40.0, 5e-4, 0.0),
])
def test_first_order_filter(y0, x0, slope, h, tau):
    y = first_order(y0, x0, slope, h, tau)
    if tau == 0.0:
        assert y == pytest.approx(x0 + slope * h)
        return
    sol = solve_ivp(lambda t, y: [(x0 + slope * t - y[0]) / tau], (0.0, h), [y0],
                    method="DOP853", rtol=1e-12, atol=1e-15)
    assert y == pytest.approx(sol.y[0, -1], abs=1e-12)
