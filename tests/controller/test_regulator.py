"""The position regulator in closed loop with an independent plant simulation.

The plant is scipy's ZOH discretisation of the state-space model (``cont2discrete``), the
DAC output acting one tick later (the computation delay), with an optional constant
disturbance at the drive input (V).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import scipy.signal
from hypothesis import example, given
from hypothesis import strategies as st

from twin.controller.dcu import dcu_as_feedforward, dcu_coefficients
from twin.controller.gains import RegulatorGains, default_gains
from twin.controller.linear import LinearAxisModel, position_gain
from twin.controller.regulator import TERMS, PositionRegulator, RegulatorStatus
from twin.errors import ConfigError

K_H = 1.0 / 600.0
TAU = 0.02
T = 5e-3
SERVO = LinearAxisModel.servo(K_H, TAU)
SERVO2 = LinearAxisModel.servo2(K_H, 0.01, 0.01, 0.4)
LSB_12 = 20.0 / 4096.0


class Plant:
    """One axis: ZOH state-space of the model, one tick of delay, input disturbance (V)."""

    def __init__(self, model: LinearAxisModel, *, disturbance: float = 0.0):
        a, b, c, d = scipy.signal.tf2ss(model.num, model.den)
        self.phi, gam, cc, _, _ = scipy.signal.cont2discrete((a, b, c, d), T, method="zoh")
        self.gam, self.c = gam[:, 0], cc[0]
        self.state = np.zeros(self.phi.shape[0])
        self.pending = 0.0
        self.disturbance = disturbance

    @property
    def position(self) -> float:
        return float(self.c @ self.state)

    def step(self, u: float) -> None:
        self.state = self.phi @ self.state + self.gam * (self.pending + self.disturbance)
        self.pending = u


def run(regulator, plants, x_ref, v_ref=None, a_ref=None, j_ref=None):
    """Close the loop for len(x_ref) ticks; references have shape (n, axes)."""
    n, axes = x_ref.shape
    zero = np.zeros_like(x_ref)
    v_ref, a_ref, j_ref = (zero if r is None else r for r in (v_ref, a_ref, j_ref))
    log = {k: np.empty((n, axes)) for k in ("x", "u", "e")}
    log["terms"] = np.empty((n, axes, len(TERMS)))
    log["status"] = np.empty(n, dtype=int)
    for i in range(n):
        x = np.array([p.position for p in plants])
        log["status"][i] = regulator.update(x_ref[i], v_ref[i], a_ref[i], j_ref[i], x)
        for k, p in enumerate(plants):
            p.step(regulator.output[k])
        log["x"][i], log["u"][i], log["e"][i] = x, regulator.output, regulator.error
        log["terms"][i] = regulator.terms
    return log


def constant(values, n):
    return np.tile(np.asarray(values, dtype=float), (n, 1))


# ------------------------------------------------------------------ linear behaviour
def test_p_loop_follows_the_linear_closed_loop():
    """P only, no DAC: each axis reproduces kp·G/(1 + kp·G) of its own model."""
    models, kp = (SERVO, SERVO2), (6000.0, 4000.0)
    reg = PositionRegulator(RegulatorGains(kp=kp, dac_bits=None), T)
    n = 800
    step = np.array([0.5e-3, -0.3e-3])
    log = run(reg, [Plant(m) for m in models], constant(step, n))
    for k, (m, g) in enumerate(zip(models, kp, strict=True)):
        numz, denz = m.discrete(T)
        expected = scipy.signal.lfilter(g * numz, denz + g * numz, np.full(n, step[k]))
        np.testing.assert_allclose(log["x"][:, k], expected, rtol=0, atol=1e-12)
    assert np.abs(log["e"][-1]).max() < 1e-12           # type 1: no error at rest


def test_terms_add_up_to_the_output_before_saturation():
    g = RegulatorGains(kp=5000.0, ki=2e4, kd=30.0, ff1=600.0, ff2=12.0, ff3=0.1,
                       dcu_alpha=(1e5, 5e5, 1e6), dac_bits=None)
    reg = PositionRegulator(g, T)
    t = np.arange(200)[:, None] * T
    log = run(reg, [Plant(SERVO), Plant(SERVO2)], 1e-3 * np.hstack([t, t**2]),
              v_ref=1e-3 * np.hstack([np.ones_like(t), 2 * t]))
    assert (log["status"] == RegulatorStatus.OK).all()
    np.testing.assert_allclose(log["terms"].sum(axis=2), log["u"], rtol=1e-12, atol=1e-15)


def test_pi_removes_the_steady_error_of_a_constant_disturbance():
    d, kp, n = 0.5, 6000.0, 1500                        # 0.5 V offset at the drive input
    target = constant([1e-3], n)
    p_only = run(PositionRegulator(RegulatorGains(kp=kp, dac_bits=None), T, n_axes=1),
                 [Plant(SERVO, disturbance=d)], target)
    assert p_only["e"][-1, 0] == pytest.approx(-d / kp, rel=1e-9)  # kp·e + d = 0 at rest
    pi = run(PositionRegulator(RegulatorGains(kp=kp, ki=3e4, dac_bits=None), T, n_axes=1),
             [Plant(SERVO, disturbance=d)], target)
    assert abs(pi["e"][-1, 0]) < 1e-9 * d / kp
    assert pi["terms"][-1, 0, 1] == pytest.approx(-d, rel=1e-9)    # the integral holds -d


class PlainPI:
    """Reference without anti-windup: integrates every tick, then clamps."""

    def __init__(self, kp, ki, limit):
        self.kp, self.ki, self.limit, self.integral = kp, ki, limit, 0.0
        self.output, self.error = np.zeros(1), np.zeros(1)
        self.terms = np.zeros((1, len(TERMS)))

    def update(self, x_ref, v_ref, a_ref, j_ref, x):
        e = x_ref[0] - x[0]
        self.integral += self.ki * T * e
        self.output[0] = min(max(self.kp * e + self.integral, -self.limit), self.limit)
        self.error[0] = e
        return 0


def test_conditional_integration_holds_the_integral_while_saturated():
    kp, ki, n = 6000.0, 3e4, 1000
    target = constant([10e-3], n)                        # 10 mm: 60 V asked, 10 V given
    gains = RegulatorGains(kp=kp, ki=ki, dac_bits=None, following_error_limit=0.1)
    aw = run(PositionRegulator(gains, T, n_axes=1), [Plant(SERVO)], target)
    ref = run(PlainPI(kp, ki, 10.0), [Plant(SERVO)], target)
    saturated = aw["status"] == RegulatorStatus.SATURATED
    assert saturated[:50].all()                          # the long saturated traverse
    integral = aw["terms"][:, 0, 1]
    pushing = saturated & (aw["e"][:, 0] > 0)
    assert np.all(integral[pushing] == 0.0)              # never grew while pushing
    overshoot_aw = -aw["e"][:, 0].min()
    overshoot_ref = -ref["e"][:, 0].min()
    assert overshoot_ref > 2e-3                          # windup: millimetres past the target
    assert overshoot_aw < 0.05 * overshoot_ref
    assert abs(aw["e"][-1, 0]) < 1e-9                    # and it still converges


# ------------------------------------------------------------------ saturation and DAC
@pytest.mark.parametrize("bits", [8, 12, 16])
def test_output_is_the_nearest_dac_code(bits):
    """Brute force: the output is the code nearest to the clamped demand."""
    lsb = 20.0 / 2**bits
    codes = np.arange(-(2 ** (bits - 1)), 2 ** (bits - 1)) * lsb
    kp = 1000.0
    rng = np.random.default_rng(bits)
    demands = np.concatenate([rng.uniform(-12.0, 12.0, 300), [10.0, -10.0, 9.999, 1e-9]])
    reg = PositionRegulator(RegulatorGains(kp=kp, dac_bits=bits, following_error_limit=1.0),
                            T, n_axes=1)
    for u in demands:
        reg.reset([0.0])
        status = reg.update([u / kp], [0.0], [0.0], [0.0], [0.0])
        expected = codes[np.argmin(np.abs(codes - np.clip(u, -10.0, 10.0)))]
        assert reg.output[0] == expected
        assert (reg.output[0] / lsb).is_integer()
        assert status == (RegulatorStatus.SATURATED if abs(u) > 10.0 else RegulatorStatus.OK)


def test_dac_mapping_of_the_reference_rig():
    g = RegulatorGains(kp=1.0, following_error_limit=math.inf)
    assert g.dac_lsb == LSB_12                           # 12 bit, ±10 V: 20 V / 4096
    reg = PositionRegulator(g, T, n_axes=2)
    reg.update([100.0, -100.0], [0, 0], [0, 0], [0, 0], [0.0, 0.0])
    assert reg.output.tolist() == [2047 * LSB_12, -2048 * LSB_12]   # 9.99512 V, -10 V
    reg.reset([0.0, 0.0])
    reg.update([0.5 * LSB_12 * 1.0001, 0.5 * LSB_12 * 0.9999], [0, 0], [0, 0], [0, 0], [0, 0])
    assert reg.output.tolist() == [LSB_12, 0.0]


# ------------------------------------------------------------------ following error
def test_following_error_trips_latches_and_zeroes_the_output():
    reg = PositionRegulator(RegulatorGains(kp=2000.0, following_error_limit=1e-3), T)
    z = [0.0, 0.0]
    assert reg.update([0.5e-3, 0.0], z, z, z, z) == RegulatorStatus.OK
    assert reg.output[0] > 0.0
    assert reg.update([0.5e-3, 1.5e-3], z, z, z, z) == RegulatorStatus.FOLLOWING_ERROR
    assert reg.tripped and reg.output.tolist() == [0.0, 0.0]
    # back within the limit: still latched, still zero, error still reported
    assert reg.update([0.2e-3, 0.0], z, z, z, z) == RegulatorStatus.FOLLOWING_ERROR
    assert reg.output.tolist() == [0.0, 0.0]
    assert reg.error.tolist() == [0.2e-3, 0.0]
    reg.reset([0.0, 0.0])
    assert not reg.tripped
    assert reg.update([0.2e-3, 0.0], z, z, z, z) == RegulatorStatus.OK
    assert reg.output[0] == pytest.approx(0.4, abs=LSB_12)


@pytest.mark.parametrize(("field", "value"), [("x_ref", math.nan), ("x", math.inf),
                                              ("v", math.nan), ("j", -math.inf)])
def test_non_finite_input_trips_without_raising(field, value):
    reg = PositionRegulator(RegulatorGains(kp=2000.0, ff1=600.0, ff3=0.1), T)
    args = {k: np.zeros(2) for k in ("x_ref", "v", "a", "j", "x")}
    args[field][1] = value
    status = reg.update(args["x_ref"], args["v"], args["a"], args["j"], args["x"])
    assert status == RegulatorStatus.INVALID_INPUT
    assert reg.output.tolist() == [0.0, 0.0] and reg.tripped


anything = st.floats(allow_nan=True, allow_infinity=True, width=64)
ticks = st.lists(st.lists(anything, min_size=10, max_size=10), min_size=1, max_size=30)


@given(ticks)
# found by a full run: after a trip, a reference and a measurement both infinite (inf − inf)
@example([[0.0] * 9 + [1.0], [math.inf] + [0.0] * 7 + [math.inf, 0.0]])
def test_update_never_raises_and_the_output_stays_a_valid_dac_code(sequence):
    reg = PositionRegulator(RegulatorGains(kp=8000.0, ki=3e4, kd=20.0, ff1=600.0, ff2=15.0,
                                           ff3=0.2, dcu_alpha=(1.2e5, 6e5, 2e6)), T)
    for row in sequence:
        x_ref, v, a, j, x = (row[i:i + 2] for i in range(0, 10, 2))
        status = reg.update(x_ref, v, a, j, x)
        assert status in tuple(RegulatorStatus)
        assert np.all(np.abs(reg.output) <= 10.0)
        assert np.all(np.mod(reg.output, LSB_12) == 0.0)
        if reg.tripped:
            assert reg.output.tolist() == [0.0, 0.0]


# ------------------------------------------------------------------ feed-forward
def ramp_error(gains: RegulatorGains, v: float, n: int = 1000) -> float:
    reg = PositionRegulator(gains, T, n_axes=1)
    t = np.arange(n)[:, None] * T
    log = run(reg, [Plant(SERVO)], v * t, v_ref=np.full((n, 1), v))
    return float(log["e"][-1, 0])


def test_ff1_of_one_over_kh_removes_the_velocity_error():
    kp, v = 6000.0, 10e-3
    assert ramp_error(RegulatorGains(kp=kp, dac_bits=None), v) == \
        pytest.approx(v / (kp * K_H), rel=1e-9)                       # 1 mm at 10 mm/s
    assert abs(ramp_error(RegulatorGains(kp=kp, ff1=1.0 / K_H, dac_bits=None), v)) \
        < 1e-9 * v / (kp * K_H)


def test_dcu_and_its_feedforward_form_give_the_same_output_on_a_cubic():
    alpha = dcu_coefficients(SERVO, T, 3)
    ff = dcu_as_feedforward(alpha, T)
    n = 100
    t = np.arange(n)[:, None] * T + 0.1
    c = (2e-3, 1e-2, 3e-2, 0.5)                     # x = c0 + c1 t + c2 t² + c3 t³ (m)
    x = c[0] + c[1] * t + c[2] * t**2 + c[3] * t**3
    v, a, j = c[1] + 2 * c[2] * t + 3 * c[3] * t**2, 2 * c[2] + 6 * c[3] * t, 6 * c[3] + 0 * t
    by_dcu = PositionRegulator(RegulatorGains(kp=0.0, dcu_alpha=alpha, dac_bits=None,
                                              following_error_limit=math.inf), T, n_axes=1)
    by_ff = PositionRegulator(RegulatorGains(kp=0.0, ff1=ff[0], ff2=ff[1], ff3=ff[2],
                                             dac_bits=None, following_error_limit=math.inf),
                              T, n_axes=1)
    out_dcu, out_ff = [], []
    for i in range(n):
        by_dcu.update(x[i], v[i], a[i], j[i], [0.0])
        by_ff.update(x[i], v[i], a[i], j[i], [0.0])
        out_dcu.append(by_dcu.terms[0, 4])
        out_ff.append(by_ff.terms[0, 3])
    # from the fourth tick on the DCU history holds four samples of the cubic
    np.testing.assert_allclose(out_dcu[3:], out_ff[3:], rtol=1e-8)


# ------------------------------------------------------------------ gain rule
def margins(model, kp):
    """Phase margin (rad) and gain margin (1) of kp·G on a dense grid, via scipy."""
    numz, denz = model.discrete(T)
    _, h = scipy.signal.freqz(kp * numz, denz, worN=np.linspace(1e-4, math.pi, 200001))
    mag, phase = np.abs(h), np.unwrap(np.angle(h))
    i = np.flatnonzero(mag < 1.0)[0]
    pm = math.pi + phase[i]
    crossings = np.flatnonzero(np.diff(np.floor((phase + math.pi) / (2 * math.pi))) != 0)
    gm = 1.0 / mag[crossings].max() if crossings.size else math.inf
    return pm, gm


@pytest.mark.parametrize("tau", [0.0, 0.005, 0.02, 0.05])
def test_position_gain_gives_the_stated_phase_margin_and_little_overshoot(tau):
    model = LinearAxisModel.servo(K_H, tau)
    kp = position_gain(model, T)
    pm, gm = margins(model, kp)
    assert math.degrees(pm) == pytest.approx(70.0, abs=0.05)
    assert gm >= 2.0
    numz, denz = model.discrete(T)
    y = scipy.signal.lfilter(kp * numz, denz + kp * numz, np.ones(2000))
    assert y.max() <= 1.01                               # ≤ 1 % overshoot, as documented
    assert abs(y[-1] - 1.0) < 1e-9


def test_position_gain_respects_the_gain_margin_on_a_resonance():
    model = LinearAxisModel.servo2(K_H, 0.01, 1.0 / 30.0, 0.1)   # ω = 30 s⁻¹, ξ = 0.1
    kp = position_gain(model, T)
    pm, gm = margins(model, kp)
    assert gm == pytest.approx(2.0, rel=1e-3)            # the cap is active …
    assert math.degrees(pm) >= 70.0 - 0.05               # … and the PM rule still holds
    numz, denz = model.discrete(T)
    assert np.abs(np.roots(denz + kp * numz)).max() < 1.0


def test_default_gains_per_axis_and_feedforward_forms():
    g = default_gains([SERVO, SERVO2], T, dcu_order=2)
    assert g.kp == (position_gain(SERVO, T), position_gain(SERVO2, T))
    np.testing.assert_allclose(g.dcu_alpha, [dcu_coefficients(SERVO, T, 2),
                                             dcu_coefficients(SERVO2, T, 2)])
    assert g.ki == g.kd == 0.0
    assert g.ff1 == g.ff2 == g.ff3 == (0.0, 0.0)
    f = default_gains(SERVO, T, ff=True)
    assert f.ff1 == pytest.approx(1.0 / K_H, rel=1e-12)
    np.testing.assert_allclose([f.ff1, f.ff2, f.ff3],
                               dcu_as_feedforward(dcu_coefficients(SERVO, T, 3), T))
    assert f.dcu_alpha == (0.0, 0.0, 0.0)
    with pytest.raises(ConfigError) as info:
        default_gains(SERVO, T, ff=True, dcu_order=1)
    assert info.value.field == "ff"


def test_default_gains_with_ff_track_a_parabola_in_the_loop():
    """The sampled-exact FF: zero steady error for a constant-acceleration reference."""
    g = dataclasses.replace(default_gains(SERVO, T, ff=True), dac_bits=None)
    n, acc = 800, 2e-3                                  # 8 mm/s after 4 s
    t = np.arange(n)[:, None] * T
    log = run(PositionRegulator(g, T, n_axes=1), [Plant(SERVO)], 0.5 * acc * t**2,
              v_ref=acc * t, a_ref=np.full((n, 1), acc))
    plain = run(PositionRegulator(dataclasses.replace(g, ff2=0.0, ff3=0.0), T, n_axes=1),
                [Plant(SERVO)], 0.5 * acc * t**2, v_ref=acc * t)
    assert abs(log["e"][-1, 0]) < 1e-9 * abs(plain["e"][-1, 0])


# ------------------------------------------------------------------ axes and validation
@pytest.mark.parametrize("n_axes", [1, 3])
def test_any_number_of_axes(n_axes):
    reg = PositionRegulator(RegulatorGains(kp=1000.0, dac_bits=None), T, n_axes=n_axes)
    ref = np.arange(1, n_axes + 1) * 1e-4
    z = np.zeros(n_axes)
    reg.update(ref, z, z, z, z.tolist())
    np.testing.assert_allclose(reg.output, 1000.0 * ref, rtol=1e-12)
    assert reg.terms.shape == (n_axes, 5)


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"kp": -1.0}, "kp"), ({"kp": math.nan}, "kp"), ({"kp": "1"}, "kp"),
    ({"kp": 1.0, "ki": -1.0}, "ki"), ({"kp": 1.0, "kd": [1.0, -1.0]}, "kd"),
    ({"kp": 1.0, "ff2": math.inf}, "ff2"), ({"kp": 1.0, "dcu_alpha": (1.0, 2.0)}, "dcu_alpha"),
    ({"kp": 1.0, "dcu_alpha": ((1.0, 2.0, math.nan),) * 2}, "dcu_alpha"),
    ({"kp": 1.0, "output_limit": 0.0}, "output_limit"),
    ({"kp": 1.0, "output_limit": (10.0, -5.0)}, "output_limit"),
    ({"kp": 1.0, "dac_bits": 0}, "dac_bits"), ({"kp": 1.0, "dac_bits": 33}, "dac_bits"),
    ({"kp": 1.0, "dac_bits": 12.0}, "dac_bits"), ({"kp": 1.0, "dac_bits": True}, "dac_bits"),
    ({"kp": 1.0, "following_error_limit": 0.0}, "following_error_limit"),
    ({"kp": 1.0, "following_error_limit": math.nan}, "following_error_limit"),
])
def test_gain_validation_names_the_field(kwargs, field):
    with pytest.raises(ConfigError) as info:
        RegulatorGains(**kwargs)
    assert info.value.field == field


@pytest.mark.parametrize(("gains", "kwargs", "field"), [
    (RegulatorGains(kp=(1.0, 2.0, 3.0)), {}, "kp"),
    (RegulatorGains(kp=1.0, dcu_alpha=((1.0, 2.0, 3.0),) * 3), {}, "dcu_alpha"),
    (RegulatorGains(kp=1.0), {"period": 0.0}, "period"),
    (RegulatorGains(kp=1.0), {"n_axes": 0}, "n_axes"),
])
def test_regulator_validation_names_the_field(gains, kwargs, field):
    args = {"period": T, **kwargs}
    period = args.pop("period")
    with pytest.raises(ConfigError) as info:
        PositionRegulator(gains, period, **args)
    assert info.value.field == field


def test_reset_and_gain_rule_validation():
    reg = PositionRegulator(RegulatorGains(kp=1.0), T)
    with pytest.raises(ConfigError) as info:
        reg.reset([0.0])
    assert info.value.field == "position"
    with pytest.raises(ConfigError) as info:
        position_gain(SERVO, T, phase_margin=math.radians(95.0))
    assert info.value.field == "phase_margin"


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_update_is_the_python_reference_bit_for_bit(seed):
    """Random references and positions through saturation, a clean run and a trip: the
    compiled ``update`` and the plain-Python ``update_reference`` keep the same state and
    give the same outputs, terms, errors and statuses, exactly (same operations, same
    order, IEEE double in both)."""
    rng = np.random.default_rng(seed)
    gains = RegulatorGains(kp=(3000.0, 4500.0), ki=(500.0, 0.0), kd=(2.0, 5.0),
                           ff1=(60.0, 40.0), ff2=0.3, ff3=1e-3,
                           dcu_alpha=((190.0, 5.0, 0.2), (210.0, 3.0, 0.1)),
                           output_limit=10.0 if seed % 2 else (10.0, 5.0),
                           dac_bits=12 if seed % 3 else None, following_error_limit=2e-3)
    fast, ref = PositionRegulator(gains, 5e-3), PositionRegulator(gains, 5e-3)
    start = rng.uniform(0.0, 0.1, 2)
    fast.reset(start)
    ref.reset(start)
    x = start.copy()
    seen = set()
    for k in range(400):
        v = rng.normal(0.0, 0.1, 2)  # ff1·v up to ±20 V: saturates now and then
        x_ref = x + rng.normal(0.0, 3e-4 if k < 380 else 5e-3, 2)  # the end trips
        args = (x_ref, v, rng.normal(0.0, 0.5, 2), rng.normal(0.0, 20.0, 2), x)
        s_fast, s_ref = fast.update(*args), ref.update_reference(*args)
        assert s_fast == s_ref
        seen.add(s_fast)
        np.testing.assert_array_equal(fast.output, ref.output)
        np.testing.assert_array_equal(fast.terms, ref.terms)
        np.testing.assert_array_equal(fast.error, ref.error)
        if not fast.tripped:
            np.testing.assert_array_equal(fast._st, ref._st)
        x = x + 0.9 * (x_ref - x)
    assert fast.tripped and ref.tripped
    assert {RegulatorStatus.OK, RegulatorStatus.SATURATED,
            RegulatorStatus.FOLLOWING_ERROR} <= seen


def test_each_axis_saturates_at_its_own_dac_full_scale():
    gains = RegulatorGains(kp=1e5, output_limit=(10.0, 2.5), dac_bits=None,
                           following_error_limit=1.0)
    reg = PositionRegulator(gains, T)
    reg.reset([0.0, 0.0])
    zero = np.zeros(2)
    assert reg.update([0.01, -0.01], zero, zero, zero, zero) == RegulatorStatus.SATURATED
    assert reg.output.tolist() == [10.0, -2.5]     # not quantised: the DAC's job
    assert gains.dac_lsb == 0.0
    assert RegulatorGains(kp=1.0, output_limit=(10.0, 2.5)).dac_lsb == (20.0 / 4096,
                                                                         5.0 / 4096)
