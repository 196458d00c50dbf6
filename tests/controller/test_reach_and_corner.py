"""The planner's two building blocks, apart from the planner: the monotone reach the
look-ahead passes rely on (`twin.controller.reach`), and the seed-001 corner model
(`twin.controller.corner`)."""

import math

import numpy as np
import pytest
import scipy.signal

from twin.config import load_machine
from twin.controller.corner import (
    RIGID_LAG_CORNER_ERROR,
    NoCornerLimit,
    SeedCornerModel,
    angle_factor,
    damping_factor,
)
from twin.controller.metrics import corner_error
from twin.controller.profiles import LAWS, Limits, max_end_speed
from twin.controller.reach import monotone_end_speed, reach_floor

CFG = load_machine("tomsk_xy")


# ------------------------------------------------------------------------ monotone reach
@pytest.mark.parametrize("law", LAWS)
def test_monotone_reach_is_the_lower_envelope_of_max_end_speed(law):
    """g(v) = min over u ≥ v of f(u), against a dense brute-force envelope."""
    rng = np.random.default_rng(11)
    for _ in range(12):
        limits = Limits(1e3, 10 ** rng.uniform(-1, 1), 10 ** rng.uniform(0, 2))
        d = 10 ** rng.uniform(-6, -1)
        floor = reach_floor(law, d, limits)
        u = np.linspace(0.0, 1.2 * max_end_speed(law, 0.0, d, limits), 3001)
        f = np.array([max_end_speed(law, x, d, limits) for x in u])
        envelope = np.minimum.accumulate(f[::-1])[::-1]
        g = np.array([monotone_end_speed(law, x, d, limits, floor) for x in u])
        assert np.all(g <= f)
        assert np.all(np.diff(g) >= -1e-12 * g[1:])                 # monotone
        np.testing.assert_allclose(g, envelope, rtol=2e-6)          # grid resolution


# ------------------------------------------------------------------------ corner model
@pytest.mark.parametrize(("angle", "expected"), [
    (0.0, 0.0), (math.pi / 6, 0.5), (-math.pi / 6, 0.5), (math.pi / 2, 1.0), (2.5, 1.0),
    (math.pi, 1.0)])
def test_angle_factor_is_the_seed_f1(angle, expected):
    assert angle_factor(angle) == pytest.approx(expected, abs=1e-15)


@pytest.mark.parametrize(("xi", "expected"), [(0.25, 0.25), (0.4, 0.4), (0.1, 0.4), (0.9, 0.9)])
def test_damping_factor_is_the_seed_expression(xi, expected):
    assert damping_factor(xi) == pytest.approx(expected, abs=1e-15)


def test_default_calibration_reproduces_a_first_order_lag_corner():
    """Simulate a first-order servo lag through a 90° corner at constant speed (scipy lsim,
    exact for the piecewise-linear reference) and measure seed 001's δ_max."""
    T, V, t0 = 0.01, 0.01, -0.2                  # the start transient dies out by t = 0
    t = np.linspace(t0, 0.1, 60001)
    ref_x = np.where(t < 0, V * (t - t0), -V * t0)     # relative to A = (V·t0, 0)
    ref_y = np.where(t < 0, 0.0, V * t)
    lag = scipy.signal.lti([1.0], [T, 1.0])
    _, x, _ = scipy.signal.lsim(lag, ref_x, t - t0)
    _, y, _ = scipy.signal.lsim(lag, ref_y, t - t0)
    err = corner_error((V * t0, 0.0), (0.0, 0.0), (0.0, 0.1 * V),
                       np.column_stack([x + V * t0, y]))
    model = SeedCornerModel(servo_time_constant=T, damping_ratio=0.4)
    assert err.delta_max / (V * T) == pytest.approx(RIGID_LAG_CORNER_ERROR, rel=2e-3)
    assert model.relative_error(math.pi / 2) == pytest.approx(err.delta_max / V, rel=2e-3)
    tol = 20e-6
    assert model.max_node_speed(math.pi / 2, tol) * model.relative_error(math.pi / 2) == \
        pytest.approx(tol)
    assert model.max_node_speed(0.0, tol) == math.inf
    assert NoCornerLimit().max_node_speed(math.pi, tol) == math.inf


def test_corner_model_from_machine_uses_the_lowest_mode():
    model = SeedCornerModel.from_machine(load_machine("laser_belt"))
    assert model.natural_frequency == pytest.approx(100.0, rel=1e-9)
    assert model.damping_ratio == 0.4
    assert model.servo_time_constant == 0.01
    stiff = SeedCornerModel.from_machine(CFG)
    assert stiff.natural_frequency > 500.0
