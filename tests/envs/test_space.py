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


# --------------------------------------------------------------------------- shapers
def _shaped(seed):
    """A random shaped variant of a preset (type, and maybe a frequency and damping)."""
    from twin.controller.shaping import SHAPERS

    rng = np.random.default_rng(seed)
    name = str(rng.choice(["tomsk_xy", "laser_belt"]))
    ov = {f"controller.shaper.{a}.type": str(rng.choice(SHAPERS)) for a in ("x", "y")}
    if name == "tomsk_xy":           # its y mode (161 Hz) lies above the Nyquist rate
        ov.update({f"controller.shaper.{a}.frequency": float(rng.uniform(20, 85))
                   for a in ("x", "y")})
    if rng.random() < 0.5:
        ov["controller.shaper.x.damping"] = float(rng.uniform(0.0, 0.6))
    cfg = load_machine(name).with_overrides(ov)
    return cfg, TuningSpace.from_machine(cfg, axis_models(cfg)), rng


@pytest.mark.parametrize("seed", range(6))
def test_a_shaped_machine_adds_its_shapers_coordinates(seed):
    from envs.space import (
        DIM,
        SHAPER_DAMPING_SPAN,
        SHAPER_FREQUENCY_SPAN,
        settings_from_dict,
    )
    from twin.controller.shaping import axis_shapers

    cfg, space, rng = _shaped(seed)
    assert space.dim == DIM + 4 and space.names[-4:] == ("sf_x", "sz_x", "sf_y", "sz_y")
    centre = [(s.frequency, s.damping) for s in axis_shapers(
        cfg.controller.shaper, cfg.axes, cfg.controller.period)]
    assert space.decode(np.zeros(space.dim)).shaper == tuple(centre)
    a = rng.uniform(-1, 1, space.dim)
    s = space.decode(a)
    for k, (f0, z0) in enumerate(centre):
        f, z = s.shaper[k]
        assert f == pytest.approx(min(space.shaper_limit, f0 * SHAPER_FREQUENCY_SPAN
                                      ** a[DIM + 2 * k]), rel=1e-12)
        assert f < 0.5 / cfg.controller.period
        assert z == pytest.approx(min(0.9, max(0.0, z0 + SHAPER_DAMPING_SPAN
                                                * a[DIM + 2 * k + 1])), abs=1e-15)
    back = space.encode(s)
    clipped = {DIM + 2 * k + 1 for k in range(2) if s.shaper[k][1] in (0.0, 0.9)} | {
        DIM + 2 * k for k in range(2) if s.shaper[k][0] == space.shaper_limit}
    keep = [i for i in range(space.dim) if i not in clipped
            and (i not in (1, 6) or a[i] > 0)]                       # ki ≤ 0 is one point
    np.testing.assert_allclose(back[keep], a[keep], atol=1e-9)
    again = settings_from_dict(s.to_dict(), space.analytic)
    assert again.shaper == s.shaper
    ov = s.overrides()
    loaded = cfg.with_overrides(ov)
    for axis, (f, z) in zip(("x", "y"), s.shaper, strict=True):
        got = getattr(loaded.controller.shaper, axis)
        assert (got.frequency, got.damping) == pytest.approx((f, z))


def test_an_unshaped_machine_keeps_eleven_coordinates():
    from envs.space import DIM

    cfg = load_machine("laser_belt").with_overrides({"controller.shaper.x.type": "zv"})
    space = TuningSpace.from_machine(cfg, axis_models(cfg))     # one axis: no coordinates
    assert space.dim == DIM and space.decode(np.zeros(DIM)).shaper is None
    assert "controller.shaper.x.frequency" not in space.decode(np.zeros(DIM)).overrides()
