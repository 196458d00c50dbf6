"""The linear axis model and the DCU: closed forms, scipy references, closed-loop simulation.

The simulated loop is built here from scipy's own ZOH discretisation of the state-space
model (``scipy.signal.cont2discrete``) and a plain Python loop, independent of
``LinearAxisModel.discrete``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from twin.controller.dcu import (
    dcu_as_feedforward,
    dcu_coefficients,
    error_coefficients,
    feedforward_gains,
)
from twin.controller.linear import LinearAxisModel, power_series_ratio
from twin.errors import ConfigError

K_H = 1.0 / 600.0        # m/s per V: 10 V ↔ 1000 rpm ↔ 16.7 mm/s on the Tomsk rig
T = 5e-3                 # s

MODELS = {
    "servo": LinearAxisModel.servo(K_H, 0.02),
    "integrator": LinearAxisModel.servo(K_H, 0.0),
    "servo2": LinearAxisModel.servo2(K_H, 0.01, 0.01, 0.4),
    "servo2-resonant": LinearAxisModel.servo2(K_H, 0.015, 1.0 / 60.0, 0.15),
    "lead-lag": LinearAxisModel([K_H * 4e-3, K_H], [1e-4, 3e-2, 1.0, 0.0]),
}


# ------------------------------------------------------------------ the linear model
@pytest.mark.parametrize(("num", "den", "field"), [
    ([1.0], [1.0, 1.0], "den"),                 # no integrator
    ([1.0], [1.0, 0.0, 0.0], "den"),            # two integrators
    ([1.0, 1.0], [1.0, 0.0], "num"),            # not strictly proper
    ([1.0], [1.0, -1.0, 0.0], "den"),           # unstable speed loop
    ([1.0, 0.0], [1.0, 1.0, 0.0], "num"),       # K_H = 0
    ([np.nan], [1.0, 1.0, 0.0], "num"),
    ([1.0], [[1.0, 0.0]], "den"),
])
def test_model_validation_names_the_field(num, den, field):
    with pytest.raises(ConfigError) as info:
        LinearAxisModel(num, den)
    assert info.value.field == field


@pytest.mark.parametrize(("args", "field"), [
    ((0.0, 0.01), "velocity_gain"), ((1.0, -0.01), "time_constant"),
    ((1.0, math.inf), "time_constant")])
def test_servo_validation(args, field):
    with pytest.raises(ConfigError) as info:
        LinearAxisModel.servo(*args)
    assert info.value.field == field


def test_servo2_rejects_undamped_mechanics():
    with pytest.raises(ConfigError) as info:
        LinearAxisModel.servo2(K_H, 0.01, 0.01, 0.0)
    assert info.value.field == "xi"


@pytest.mark.parametrize("name", sorted(MODELS))
def test_velocity_gain_is_the_limit_of_p_w0(name):
    m = MODELS[name]
    p = 1e-7
    assert m.velocity_gain == pytest.approx(K_H, rel=1e-12)
    assert (p * np.polyval(m.num, p) / np.polyval(m.den, p)).real == pytest.approx(K_H, rel=1e-5)


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("delay", [0, 1, 2])
def test_discrete_matches_scipy_zoh_with_delay(name, delay):
    m = MODELS[name]
    numz, denz = m.discrete(T, delay_ticks=delay)
    ref_num, ref_den, _ = scipy.signal.cont2discrete((m.num, m.den), T, method="zoh")
    ref_num = np.concatenate([np.zeros(delay), ref_num.ravel()])
    ref_den = np.concatenate([ref_den, np.zeros(delay)])
    assert denz.size == numz.size == ref_den.size
    np.testing.assert_allclose(denz, ref_den, rtol=1e-9, atol=1e-12)
    # scipy forms the numerator by cancellation; 1e-7 of the largest coefficient is its noise
    np.testing.assert_allclose(numz, ref_num, rtol=0, atol=1e-7 * np.abs(ref_num).max())


@pytest.mark.parametrize("name", sorted(MODELS))
def test_discrete_step_response_samples_the_continuous_one(name):
    """Brute force: the sampled continuous step response equals the pulse TF's response."""
    m = MODELS[name]
    n = 200
    numz, denz = m.discrete(T, delay_ticks=0)
    y = scipy.signal.lfilter(numz, denz, np.ones(n))
    t = np.arange(n) * T
    _, y_ref, _ = scipy.signal.lsim((m.num, m.den), np.ones(n), t)
    np.testing.assert_allclose(y, y_ref, rtol=1e-6, atol=1e-9 * np.abs(y_ref).max())


@pytest.mark.parametrize("name", sorted(MODELS))
def test_frequency_response_matches_scipy(name):
    m = MODELS[name]
    w = np.logspace(-1, math.log10(math.pi / T), 50)
    _, h = scipy.signal.freqs(m.num, m.den, w)
    np.testing.assert_allclose(m.frequency_response(w), h, rtol=1e-12)
    numz, denz = m.discrete(T)
    _, hz = scipy.signal.freqz(numz, denz, w * T)
    np.testing.assert_allclose(m.frequency_response(w, period=T), hz, rtol=1e-8)


def test_power_series_ratio_against_geometric_series():
    # 1 / (1 - x)^2 = Σ (k+1) x^k ;  (1 + x) / (1 - 2x) = 1 + 3x + 6x² + 12x³ …
    np.testing.assert_allclose(power_series_ratio([1.0], [1.0, -2.0, 1.0], 6),
                               np.arange(1, 7))
    np.testing.assert_allclose(power_series_ratio([1.0, 1.0], [1.0, -2.0], 4), [1, 3, 6, 12])


# ------------------------------------------------------------------ DCU coefficients
def closed_form_servo(k_h: float, tau: float, period: float, delay: int) -> np.ndarray:
    """α for K_H/(p(τp+1)) with ZOH and ``delay`` ticks, derived by hand.

    With s = z⁻¹ = 1 - w, a = e^(-T/τ), r = τ/T, γ = a/(1-a), the ZOH pulse TF is
    K_H·(b1·s + b2·s²)/((1-s)(1-a·s)) with b1 + b2 = T(1-a), b2 = τ(1-a) - aT; so
    1/H(w) = (1 + γw) / (K_H·T·(1-w)^(d+1)·(1 - βw)), β = r - γ. Expanding:
    α1 = 1/(K_H T), α2 = (d + 1 + r)/(K_H T),
    α3 = ((d+1)(d+2)/2 + (d+1)·r + r² - r·γ)/(K_H T).
    """
    r = tau / period
    r_gamma = 0.0 if tau == 0.0 else r / math.expm1(period / tau)
    return np.array([1.0, delay + 1 + r,
                     (delay + 1) * (delay + 2) / 2 + (delay + 1) * r + r * r - r_gamma]) \
        / (k_h * period)


@pytest.mark.parametrize("delay", [0, 1, 2])
@pytest.mark.parametrize("tau", [0.0, 1e-3, 5e-3, 0.02, 0.2])
@pytest.mark.parametrize("period", [1e-3, 5e-3])
def test_dcu_matches_hand_derived_closed_forms(delay, tau, period):
    alpha = dcu_coefficients(LinearAxisModel.servo(K_H, tau), period, 3, delay_ticks=delay)
    np.testing.assert_allclose(alpha, closed_form_servo(K_H, tau, period, delay), rtol=1e-9)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_alpha1_is_seed_closed_form(name):
    alpha = dcu_coefficients(MODELS[name], T, 1)
    assert alpha[0] == pytest.approx(1.0 / (K_H * T), rel=1e-12)
    np.testing.assert_array_equal(alpha[1:], 0.0)


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_lower_orders_are_prefixes_of_higher(order):
    full = dcu_coefficients(MODELS["servo2"], T, 3)
    alpha = dcu_coefficients(MODELS["servo2"], T, order)
    np.testing.assert_allclose(alpha[:order], full[:order], rtol=1e-12)
    np.testing.assert_array_equal(alpha[order:], 0.0)


@pytest.mark.parametrize("order", [-1, 4, 1.5, True])
def test_order_is_validated(order):
    with pytest.raises(ConfigError) as info:
        dcu_coefficients(MODELS["servo"], T, order)
    assert info.value.field == "order"


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize(("kp", "ki", "kd"), [(3000.0, 0.0, 0.0), (6000.0, 0.0, 20.0),
                                              (4000.0, 2e4, 0.0)])
def test_error_coefficients_vanish_up_to_the_order(name, kp, ki, kd):
    m = MODELS[name]
    for order in range(4):
        c = error_coefficients(m, T, dcu_coefficients(m, T, order), kp=kp, ki=ki, kd=kd,
                               count=6)
        scale = 1.0 / (kp * K_H * T)               # c1 of the plain P loop
        np.testing.assert_allclose(c[: order + 1], 0.0, atol=1e-9 * scale)
        # an integrator adds one more vanishing coefficient, never fewer
        first = order + 1 + (ki > 0)
        assert abs(c[first]) > 1e-6 * scale


def test_error_coefficient_c1_of_p_loop_is_the_velocity_error():
    kp = 3000.0
    c = error_coefficients(MODELS["servo"], T, kp=kp)
    assert c[0] == 0.0
    assert c[1] == pytest.approx(1.0 / (kp * K_H * T), rel=1e-12)   # e = v/(kp·K_H)


# ------------------------------------------------------------------ simulation of C0..C3
def simulate_loop(model: LinearAxisModel, kp: float, alpha: np.ndarray,
                  reference: np.ndarray) -> np.ndarray:
    """Plain loop: P regulator + DCU on the reference, ZOH plant, one tick of delay."""
    a, b, c, d = scipy.signal.tf2ss(model.num, model.den)
    phi, gam, cc, _, _ = scipy.signal.cont2discrete((a, b, c, d), T, method="zoh")
    s = np.zeros(phi.shape[0])
    hist = np.zeros(4)                 # x_ref(i), x_ref(i-1), x_ref(i-2), x_ref(i-3)
    u_prev = 0.0
    err = np.empty(reference.size)
    for i, r in enumerate(reference):
        x = float(cc[0] @ s)
        e = r - x
        hist = np.concatenate([[r], hist[:3]])
        d1 = hist[0] - hist[1]
        d2 = hist[0] - 2 * hist[1] + hist[2]
        d3 = hist[0] - 3 * hist[1] + 3 * hist[2] - hist[3]
        u = kp * e + alpha[0] * d1 + alpha[1] * d2 + alpha[2] * d3
        s = phi @ s + gam[:, 0] * u_prev          # the output computed now acts next tick
        u_prev = u
        err[i] = e
    return err


@pytest.mark.parametrize("name", ["servo", "servo2", "lead-lag"])
@pytest.mark.parametrize("degree", [1, 2, 3])
def test_order_k_dcu_zeroes_the_error_for_degree_k_references(name, degree):
    m = MODELS[name]
    n = 1200
    t = np.arange(n) * T
    reference = 0.01 * t**degree                     # 10 mm at 1 s
    d_n = math.factorial(degree) * 0.01 * T**degree  # ∇^degree of the reference (m)
    kps = (4000.0, 7000.0)                           # α must not depend on kp
    for kp in kps:
        plain = simulate_loop(m, kp, np.zeros(3), reference)
        scale = np.abs(plain).max()
        below = dcu_coefficients(m, T, degree - 1)
        exact = dcu_coefficients(m, T, degree)
        e_below = simulate_loop(m, kp, below, reference)
        e_exact = simulate_loop(m, kp, exact, reference)
        # order k-1 leaves the constant error c_k·∇^k x_ref (seed 000's C_k ≠ 0)
        c = error_coefficients(m, T, below, kp=kp, count=degree + 1)
        assert e_below[-1] == pytest.approx(c[degree] * d_n, rel=1e-6)
        # order k: C0..Ck = 0, the steady-state error vanishes
        residual = np.abs(e_exact[-50:]).max()
        assert residual <= 1e-9 * scale
        assert residual <= 1e-6 * abs(e_below[-1])


@pytest.mark.parametrize("kp", [4000.0, 7000.0])
def test_ramp_error_of_p_loop_is_v_over_kv(kp):
    m = MODELS["servo"]
    v = 0.01
    e = simulate_loop(m, kp, np.zeros(3), v * np.arange(1200) * T)
    assert e[-1] == pytest.approx(v / (kp * K_H), rel=1e-9)


# ------------------------------------------------------------------ feed-forward forms
def test_dcu_as_feedforward_equals_dcu_on_a_cubic():
    rng = np.random.default_rng(7)
    alpha = rng.normal(size=(2, 3)) * [1e5, 1e6, 1e6]
    coeffs = rng.normal(size=4) * [1e-2, 1e-2, 1e-1, 1.0]     # x = c0 + c1 t + c2 t² + c3 t³
    t0 = 0.37
    x = np.polynomial.Polynomial(coeffs)
    v, a, j = x.deriv(1), x.deriv(2), x.deriv(3)
    h = x(t0 - T * np.arange(4))
    nabla = np.array([h[0] - h[1], h[0] - 2 * h[1] + h[2], h[0] - 3 * h[1] + 3 * h[2] - h[3]])
    ff = dcu_as_feedforward(alpha, T)
    assert ff.shape == (2, 3)
    np.testing.assert_allclose(ff @ [v(t0), a(t0), j(t0)], alpha @ nabla, rtol=1e-9)


def test_dcu_feedforward_of_the_servo_compensates_lag_and_delay():
    tau = 0.02
    ff = dcu_as_feedforward(dcu_coefficients(MODELS["servo"], T, 3), T)
    assert ff[0] == pytest.approx(1.0 / K_H, rel=1e-12)
    # τ of the servo + T/2 of the ZOH + T of the computation delay
    assert ff[1] == pytest.approx((tau + 1.5 * T) / K_H, rel=1e-12)


@pytest.mark.parametrize(("model", "expected"), [
    (LinearAxisModel.servo(K_H, 0.02), [1 / K_H, 0.02 / K_H, 0.0]),
    (LinearAxisModel.servo2(K_H, 0.01, 0.004, 0.3),
     [1 / K_H, (0.01 + 2 * 0.3 * 0.004) / K_H, (0.004**2 + 2 * 0.3 * 0.004 * 0.01) / K_H]),
    # W0 = K(1 + b p)/(p(1 + a p)):  1/W0 = p/K·(1 + (a-b)p - b(a-b)p² + …)
    (LinearAxisModel([K_H * 0.002, K_H], [0.03, 1.0, 0.0]),
     [1 / K_H, (0.03 - 0.002) / K_H, -0.002 * (0.03 - 0.002) / K_H]),
])
def test_feedforward_gains_are_the_ideal_inverse(model, expected):
    np.testing.assert_allclose(feedforward_gains(model), expected, rtol=1e-12, atol=1e-12)


def test_alpha_shape_is_validated():
    with pytest.raises(ConfigError) as info:
        dcu_as_feedforward([1.0, 2.0], T)
    assert info.value.field == "alpha"
    with pytest.raises(ConfigError) as info:
        error_coefficients(MODELS["servo"], T, [1.0], kp=1.0)
    assert info.value.field == "alpha"
    with pytest.raises(ConfigError) as info:
        error_coefficients(MODELS["servo"], T, kp=0.0)
    assert info.value.field == "kp"


def test_the_canonical_state_space_is_scipys():
    """``controller.linear`` builds the controller canonical form itself (importing
    ``scipy.signal`` costs every process a second): equal to ``scipy.signal.tf2ss`` on
    random proper transfer functions of order 1-5."""
    from twin.controller.linear import _canonical

    rng = np.random.default_rng(7)
    for _ in range(200):
        m = int(rng.integers(1, 6))
        den = rng.normal(size=m + 1)
        num = rng.normal(size=int(rng.integers(1, m + 2)))
        for ours, ref in zip(_canonical(num, den), scipy.signal.tf2ss(num, den), strict=True):
            np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-12)
