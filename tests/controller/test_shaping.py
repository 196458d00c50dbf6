"""Input shapers (``twin.controller.shaping``) against independent references: the closed
forms' defining properties, an integrated damped oscillator, a brute-force convolution, and
the compiled tick against the Python tick with shaping on (bit for bit)."""

from __future__ import annotations

import itertools
import math
import os

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import argrelmax

from twin.config import load_machine
from twin.config.shaper_settings import SHAPER_TYPES, profile_overrides, split_profile
from twin.controller.controller import Controller, ControllerStatus
from twin.controller.geometry import Line
from twin.controller.io import Inputs
from twin.controller.planner import MotionBlock
from twin.controller.shaping import (
    SHAPERS,
    V_TOL,
    ReferenceShaper,
    circle_error,
    design,
    residual_vibration,
)
from twin.errors import ConfigError

CI = bool(os.environ.get("CI"))
ZERO_AT_DESIGN = ("zv", "mzv", "zvd", "2hump-ei")


def _cases(n: int, seed: int, zeta_max: float = 0.5):
    rng = np.random.default_rng(seed)
    return [(str(rng.choice(SHAPERS)), float(rng.uniform(2.0, 120.0)),
             float(rng.uniform(0.0, zeta_max))) for _ in range(n)]


def test_the_config_names_every_shaper():
    assert SHAPER_TYPES == ("none", *SHAPERS)


@pytest.mark.parametrize(("name", "f", "z"), _cases(40, 1))
def test_impulses_sum_to_one_start_at_zero_and_are_positive(name, f, z):
    s = design(name, f, z)
    assert math.isclose(sum(s.amplitudes), 1.0, abs_tol=1e-14)
    assert s.times[0] == 0.0 and all(np.diff(s.times) > 0) and min(s.amplitudes) > 0


@pytest.mark.parametrize(("name", "f", "z"), _cases(40, 2))
def test_residual_vibration_at_the_design_point(name, f, z):
    s = design(name, f, z)
    v = s.residual(f)
    if name in ZERO_AT_DESIGN:
        assert v < 1e-12
    else:
        assert math.isclose(v, s.design_residual(), rel_tol=1e-9)
        assert math.isclose(design(name, f, 0.0).residual(f), V_TOL, rel_tol=1e-12)


@pytest.mark.parametrize("name", ("ei", "2hump-ei", "3hump-ei"))
def test_the_undamped_ei_humps_reach_the_tolerance_exactly(name):
    """Each hump between the zeros of an undamped EI shaper peaks at V_TOL (the property its
    closed form is solved for), found here by a dense search."""
    s = design(name, 50.0, 0.0)
    f = np.linspace(20.0, 80.0, 600_001)
    v = s.residual(f)
    peaks = argrelmax(v)[0]
    peaks = peaks[(v[peaks] < 0.5)]                       # the humps, not the outer skirts
    assert len(peaks) == {"ei": 1, "2hump-ei": 2, "3hump-ei": 3}[name]
    assert np.allclose(v[peaks], V_TOL, rtol=1e-6)


def _oscillator_residual(amplitudes, times, f, z) -> float:
    """Amplitude of the vibration a damped oscillator keeps when the shaped step ends,
    relative to the vibration an unshaped step starts with (solve_ivp; Singer & Seering's
    normalisation)."""
    w = 2 * math.pi * f

    def rhs(t, y, amps):
        u = sum(a for a, ti in zip(amps, times, strict=True) if t >= ti)
        return [y[1], w * w * (u - y[0]) - 2 * z * w * y[1]]

    def amplitude(amps):
        end = times[-1]
        sol = solve_ivp(rhs, (0.0, end + 1e-9), [0.0, 0.0], args=(amps,), rtol=1e-11,
                        atol=1e-13, max_step=min(1.0 / (40 * f), end / 8 + 1e-6))
        x, v = sol.y[0, -1] - 1.0, sol.y[1, -1]
        wd = w * math.sqrt(1 - z * z)
        return math.hypot(x, (v + z * w * x) / wd)       # the free response's envelope

    unshaped = amplitude([1.0] + [0.0] * (len(times) - 1)) * math.exp(z * w * times[-1])
    return amplitude(list(amplitudes)) / unshaped


@pytest.mark.parametrize(("name", "f", "z"), _cases(3 if CI else 10, 3, 0.3))
def test_residual_vibration_matches_an_integrated_oscillator(name, f, z):
    s = design(name, f, z)
    rng = np.random.default_rng(int(f * 1000))
    f_mode, z_mode = f * rng.uniform(0.7, 1.3), min(0.6, z * rng.uniform(0.5, 1.5))
    sim = _oscillator_residual(s.amplitudes, s.times, f_mode, z_mode)
    assert sim == pytest.approx(s.residual(f_mode, z_mode), abs=2e-6)


def test_delay_duration_and_lag():
    """A shaped step reaches its end exactly after the taps' last delay; a shaped ramp
    lags by the taps' centroid."""
    rng = np.random.default_rng(4)
    for name, f, z in _cases(20, 4, 0.4):
        period = float(rng.uniform(0.5e-3, 0.45 / f))
        shaper = design(name, f, z)
        rs = ReferenceShaper((shaper, shaper), period)
        index, weight = shaper.taps(period)
        assert math.isclose(weight.sum(), 1.0, abs_tol=1e-14)
        assert abs(index[-1] * period - shaper.duration) < period
        assert math.isclose(float(np.dot(weight, index)) * period, shaper.lag,
                            rel_tol=1e-9, abs_tol=1e-12)
        rs.reset((0.0, 0.0))
        n = int(index[-1]) + 20
        out = np.zeros((n, 2))
        for k in range(n):               # a step of 1 m on x, a ramp of 1 m/s on y
            p, v = np.array([1.0, k * period]), np.array([0.0, 1.0])
            rs.apply(p, v, np.zeros(2), np.zeros(2))
            out[k] = p
        assert out[int(index[-1]), 0] == 1.0 and np.all(out[int(index[-1]):, 0] == 1.0)
        assert np.all(out[:int(index[-1]), 0] < 1.0)
        late = np.arange(int(index[-1]), n) * period
        assert np.allclose(out[int(index[-1]):, 1], late - shaper.lag, atol=1e-12)


def test_the_shaped_reference_is_the_convolution():
    """Random references through random shapers of each axis against np.convolve of the
    taps; p, v, a and j alike."""
    rng = np.random.default_rng(5)
    for (nx, fx, zx), (ny, fy, zy) in itertools.pairwise(_cases(12, 5)):
        period = float(rng.uniform(1e-3, 0.4 / max(fx, fy)))
        shapers = (design(nx, fx, zx), design(ny, fy, zy))
        rs = ReferenceShaper(shapers, period)
        x0 = rng.uniform(-1, 1, 2)
        rs.reset(x0)
        n = 300
        raw = rng.normal(size=(n, 4, 2))
        raw[:, 0] += x0
        out = np.empty_like(raw)
        for k in range(n):
            p, v, a, j = (raw[k, c].copy() for c in range(4))
            rs.apply(p, v, a, j)
            out[k] = p, v, a, j
        for axis, shaper in enumerate(shapers):
            index, weight = shaper.taps(period)
            kernel = np.zeros(index[-1] + 1)
            kernel[index] = weight
            for c in range(4):
                before = np.full(index[-1], x0[axis] if c == 0 else 0.0)
                full = np.convolve(np.concatenate([before, raw[:, c, axis]]), kernel)
                expect = full[index[-1]:index[-1] + n]
                assert np.allclose(out[:, c, axis], expect, rtol=1e-12, atol=1e-12)


def test_splitting_an_impulse_between_samples_costs_at_most_wt_squared_over_8():
    rng = np.random.default_rng(6)
    for name, f, z in _cases(30, 6, 0.3):
        period = float(rng.uniform(0.02, 0.3)) / f           # ωT from 0.13 to 1.9
        s = design(name, f, z)
        gap = abs(s.discrete(period).residual(f) - s.residual(f))
        assert gap <= (2 * math.pi * f * period) ** 2 / 8 + 1e-12


def test_one_shaper_on_both_axes_keeps_lines_and_shrinks_circles_as_predicted():
    rng = np.random.default_rng(8)
    for name, f, z in _cases(8, 8, 0.3):
        period = 1e-3
        s = design(name, f, z)
        rs = ReferenceShaper((s, s), period)
        # a line with a speed change: every shaped point stays on it
        u = np.array([math.cos(1.1), math.sin(1.1)])
        rs.reset((0.0, 0.0))
        for k in range(400):
            dist = 0.05 * (k * period) ** 2 if k < 200 else 0.05 * 0.04 + 0.02 * (
                k - 200) * period
            p = dist * u
            rs.apply(p, np.zeros(2), np.zeros(2), np.zeros(2))
            assert abs(p[0] * u[1] - p[1] * u[0]) < 1e-15
        # a circle in steady state: the radius shrinks by circle_error
        radius, speed = float(rng.uniform(2e-3, 50e-3)), float(rng.uniform(0.005, 0.05))
        omega = speed / radius
        rs.reset((radius, 0.0))
        t = np.arange(6000) * period
        for tk in t:
            p = radius * np.array([math.cos(omega * tk), math.sin(omega * tk)])
            rs.apply(p, np.zeros(2), np.zeros(2), np.zeros(2))
        shrink = radius - math.hypot(*p)
        assert shrink == pytest.approx(circle_error(s.discrete(period), radius, speed),
                                       rel=1e-6, abs=1e-12)
        sigma2 = s.spread**2
        assert circle_error(s, radius, speed) == pytest.approx(
            speed**2 * sigma2 / (2 * radius), rel=0.25)


def test_residual_vibration_of_one_impulse_is_one():
    assert residual_vibration([1.0], [0.0], np.array([3.0, 40.0]), 0.2) == pytest.approx(1.0)


# --------------------------------------------------------------------------- settings
@pytest.mark.parametrize(("text", "law", "shaper"), [
    ("trapezoid", "trapezoid", None), ("trapezoid+mzv", "trapezoid", "mzv"),
    ("Jerk_Limited+ZV", "jerk-limited", "zv"), ("parabolic+2hump_ei", "parabolic", "2hump-ei"),
    ("cosine+none", "cosine", "none")])
def test_law_plus_shaper(text, law, shaper):
    assert split_profile(text) == (law, shaper)


@pytest.mark.parametrize(("text", "words"), [
    ("trapezoid+foo", "unknown shaper 'foo'"), ("bogus+zv", "unknown law 'bogus'"),
    ("trapezoid+zv+ei", "LAW+SHAPER"), ("+zv", "LAW+SHAPER")])
def test_bad_profiles_name_the_field(text, words):
    with pytest.raises(ConfigError) as exc:
        profile_overrides(text, "--profile")
    assert exc.value.field == "--profile" and words in exc.value.message


@pytest.mark.parametrize(("key", "value", "field"), [
    ("controller.shaper.x.frequency", 150.0, "controller.shaper.x.frequency"),
    ("controller.shaper.y.damping", -0.1, "controller.shaper.y.damping"),
    ("controller.shaper.y.type", "foo", "controller.shaper.y.type")])
def test_bad_shaper_settings_name_the_field(key, value, field):
    with pytest.raises(ConfigError) as exc:
        load_machine("laser_belt").with_overrides({key: value})
    assert exc.value.field == field


def test_a_model_mode_above_nyquist_is_refused_when_no_frequency_is_set():
    cfg = load_machine("tomsk_xy").with_overrides({"controller.shaper.y.type": "zv",
                                                   "controller.period": 0.01})
    with pytest.raises(ConfigError) as exc:
        Controller.from_machine(cfg, None)
    assert exc.value.field == "controller.shaper.y.frequency"


# --------------------------------------------------------------------------- the ticks
def _chord_run(compiled: bool, seed: int) -> Controller:
    """A controller with random shapers on random chords, fed a servo that follows its DAC
    (no plant: cheap)."""
    rng = np.random.default_rng(seed)
    cfg = load_machine("tomsk_xy")
    start = np.array((0.05, 0.04))
    heading, points = 0.0, [start]
    for _ in range(60 if CI else 200):
        heading += rng.uniform(-0.8, 0.8)
        points.append(points[-1] + rng.uniform(0.05e-3, 0.5e-3) * np.array(
            (math.cos(heading), math.sin(heading))))
    blocks = [MotionBlock(Line(tuple(a), tuple(b)), 0.01) for a, b in
              itertools.pairwise(points)]
    (nx, fx, zx), (ny, fy, zy) = _cases(2, seed, 0.4)
    shapers = (design(nx, min(fx, 90.0), zx), design(ny, min(fy, 90.0), zy))
    ctrl = Controller.from_machine(cfg, blocks, start=tuple(start), compiled=compiled,
                                   profile=str(rng.choice(["trapezoid", "jerk-limited"])),
                                   shapers=shapers)
    cpm = np.array([cfg.axes[a].counts_per_metre for a in ("x", "y")])
    kh = np.array([1.0 / cfg.axes[a].volts_per_speed for a in ("x", "y")])
    x, inputs = start.copy(), Inputs()
    while not ctrl.done:
        inputs.encoder_counts[:] = np.floor(x * cpm).astype(np.int64) % (1 << 32)
        x = x + kh * ctrl.tick(inputs).dac_volts * ctrl.period
    return ctrl


@pytest.mark.parametrize("seed", range(2 if CI else 6))
def test_the_compiled_tick_gives_the_python_ticks_bits_with_shaping(seed):
    reference, compiled = _chord_run(False, seed), _chord_run(True, seed)
    assert reference.status == compiled.status == ControllerStatus.FINISHED
    assert reference.shaper is not None
    a, b = reference.record.as_arrays(), compiled.record.as_arrays()
    for name in a:
        assert np.array_equal(a[name].view(np.int64) if a[name].dtype == np.float64
                              else a[name], b[name].view(np.int64) if b[name].dtype ==
                              np.float64 else b[name]), name
    # the shaped reference ends exactly on the program's end point, at rest
    end = a["ref_position"][-1]
    assert np.array_equal(end, reference.interpolator.reference.position)
