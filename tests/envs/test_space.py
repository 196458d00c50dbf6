"""The tuning space: zero is the analytic design, the ranges are as documented, decode and
encode are inverse, bad actions are refused."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from envs.space import ALPHA_SPAN, KI_DECADES, TuningSettings, TuningSpace, check_action
from twin.config import load_machine
from twin.controller.gains import default_gains
from twin.errors import ConfigError
from twin.session.run import axis_models


@pytest.fixture(scope="module", params=["tomsk_xy", "laser_belt"])
def machine(request):
    cfg = load_machine(request.param)
    models = axis_models(cfg)
    return cfg, models, TuningSpace.from_machine(cfg, models)


def test_zero_action_is_the_analytic_design(machine):
    cfg, models, space = machine
    ref = default_gains(models, cfg.controller.period, dcu_order=3)
    s = space.decode(np.zeros(space.dim))
    np.testing.assert_allclose(s.gains.kp, ref.kp, rtol=1e-15)
    np.testing.assert_allclose(s.gains.dcu_alpha, ref.dcu_alpha, rtol=1e-15)
    assert s.gains.ki == (0.0, 0.0)
    assert s.max_jerk == cfg.controller.limits.max_jerk
    # each axis saturates at its own DAC's full scale; the DAC (the plant) quantises
    assert s.gains.output_limit == (cfg.axes["x"].dac.full_scale, cfg.axes["y"].dac.full_scale)
    assert s.gains.dac_bits is None
    assert s.gains.following_error_limit == cfg.controller.regulator.following_error_limit


def test_range_ends(machine):
    cfg, models, space = machine
    kp0 = np.array(space.analytic.kp)
    alpha0 = np.array(space.analytic.dcu_alpha)
    hi, lo = space.decode(np.ones(space.dim)), space.decode(-np.ones(space.dim))
    np.testing.assert_allclose(hi.gains.kp, kp0 * 4.0, rtol=1e-12)
    np.testing.assert_allclose(lo.gains.kp, kp0 / 4.0, rtol=1e-12)
    assert hi.max_jerk == pytest.approx(4.0 * cfg.controller.limits.max_jerk, rel=1e-12)
    assert lo.max_jerk == pytest.approx(cfg.controller.limits.max_jerk / 4.0, rel=1e-12)
    kv = kp0 * np.array([m.velocity_gain for m in models])
    np.testing.assert_allclose(hi.gains.ki, kp0 * kv, rtol=1e-12)   # a = 1: kp0·K_v
    assert lo.gains.ki == (0.0, 0.0)                                  # a <= 0: off
    span = np.array(ALPHA_SPAN)
    np.testing.assert_allclose(hi.gains.dcu_alpha, alpha0 * (1 + span), rtol=1e-12)
    np.testing.assert_allclose(lo.gains.dcu_alpha, alpha0 * (1 - span), rtol=1e-12)


def test_ki_is_log_scaled_above_zero(machine):
    _, models, space = machine
    a = np.zeros(space.dim)
    a[1] = 0.5
    kp0 = space.analytic.kp[0]
    expected = kp0 * kp0 * models[0].velocity_gain * 10 ** (-KI_DECADES / 2)
    assert space.decode(a).gains.ki[0] == pytest.approx(expected, rel=1e-12)


_TOMSK = load_machine("tomsk_xy")
_SPACE = TuningSpace.from_machine(_TOMSK, axis_models(_TOMSK))


@given(st.lists(st.floats(-1.0, 1.0), min_size=11, max_size=11))
def test_encode_inverts_decode(values):
    space = _SPACE
    a = np.array(values)
    a[[1, 6]] = np.where(a[[1, 6]] <= 1e-9, 0.0, a[[1, 6]])  # ki's dead zone maps to 0
    np.testing.assert_allclose(space.encode(space.decode(a)), a, atol=1e-9)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_actions_are_refused(bad):
    a = np.zeros(11)
    a[4] = bad
    with pytest.raises(ValueError, match=r"action\[4\]"):
        check_action(a, 11)


def test_wrong_length_and_clipping():
    with pytest.raises(ValueError, match="11 entries"):
        check_action(np.zeros(10), 11)
    np.testing.assert_array_equal(check_action([2.0, -3.0, 0.5], 3), [1.0, -1.0, 0.5])


def test_settings_validation(machine):
    _, _, space = machine
    with pytest.raises(ConfigError, match="max_jerk"):
        TuningSettings(space.analytic, -1.0)
    with pytest.raises(ConfigError, match="kp_span"):
        TuningSpace(space.analytic, 5.0, (1.0, 1.0), kp_span=1.0)
