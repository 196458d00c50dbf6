"""The shapers' corner cut (``twin.controller.shaped_corner``) against the controller's own
FIR run over a finely sampled corner and the metrics' exact contour error."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.controller.corner import SeedCornerModel
from twin.controller.geometry import Line
from twin.controller.metrics import contour_error
from twin.controller.shaped_corner import ShapedCornerModel, shaper_corner_error
from twin.controller.shaping import SHAPERS, ReferenceShaper, design


def _filtered_corner(shapers, angle, theta, period):
    """The unit-speed corner through ``ReferenceShaper`` at ``period``: its largest
    contour error from the two legs (s, per unit speed)."""
    span = max(s.duration for s in shapers if s is not None)
    u_in = np.array([math.cos(theta), math.sin(theta)])
    u_out = np.array([math.cos(theta + angle), math.sin(theta + angle)])
    t = np.arange(-2 * span, 3 * span, period)
    raw = np.where(t[:, None] < 0, t[:, None] * u_in, t[:, None] * u_out)
    rs = ReferenceShaper(shapers, period)
    rs.reset(raw[0])
    out = np.empty_like(raw)
    z = np.zeros(2)
    for k, p in enumerate(raw):
        q = p.copy()
        rs.apply(q, z.copy(), z.copy(), z.copy())
        out[k] = q
    path = [Line(tuple(-10 * span * u_in), (0.0, 0.0)), Line((0.0, 0.0),
                                                              tuple(10 * span * u_out))]
    return float(contour_error(path, out).max())


@pytest.mark.parametrize("seed", range(6))
def test_the_corner_cut_matches_the_filter(seed):
    rng = np.random.default_rng(seed)
    name = str(rng.choice(SHAPERS))
    s = design(name, float(rng.uniform(5, 60)), float(rng.uniform(0, 0.5)))
    other = s if seed % 2 == 0 else design(str(rng.choice(SHAPERS)),
                                           float(rng.uniform(5, 60)), 0.1)
    angle = float(rng.uniform(0.1, 3.0))
    kappa = float(shaper_corner_error((s, other), angle))
    period = min(s.duration, other.duration) / 400
    # the worst orientation over the eight the model scans (one when the shapers agree)
    thetas = [0.0] if other is s else np.linspace(0.0, math.pi, 8, endpoint=False)
    brute = max(_filtered_corner((s, other), angle, th, period) for th in thetas)
    assert kappa == pytest.approx(brute, rel=0.02, abs=1e-6 * s.duration)


def test_a_reversal_is_not_cut_and_the_model_only_slows():
    s = design("zvd", 20.0, 0.2)
    assert float(shaper_corner_error((s, s), math.pi)) < 1e-12
    base = SeedCornerModel(servo_time_constant=0.02)
    model = ShapedCornerModel(base, (s, s))
    for angle in np.linspace(0.05, math.pi, 20):
        v, v0 = model.max_node_speed(angle, 50e-6), base.max_node_speed(angle, 50e-6)
        assert v <= v0
        # the relative errors add: tolerance / v = tolerance / v0 + κ(α)
        assert 50e-6 / v == pytest.approx(50e-6 / v0 + model.relative_error(angle), rel=1e-12)


def test_the_curve_cap_keeps_a_shaped_circle_within_its_share():
    """At the centripetal acceleration ``curve_acceleration`` allows, a circle through the
    shapers shrinks by about SHAPER_SHARE·tolerance (``circle_error``, exact for the
    steady circle), for random shapers, radii and tolerances; and the planner's segment caps
    hold v²/R to it."""
    from twin.controller.geometry import Arc
    from twin.controller.profiles import Limits
    from twin.controller.segment_limits import SegmentLimits
    from twin.controller.shaped_corner import SHAPER_SHARE, curve_acceleration
    from twin.controller.shaping import circle_error

    rng = np.random.default_rng(11)
    for _ in range(20):
        s = design(str(rng.choice(SHAPERS)), float(rng.uniform(5, 80)),
                   float(rng.uniform(0, 0.5)))
        tol = float(rng.uniform(5e-6, 100e-6))
        a = curve_acceleration((s, None), tol)
        radius = float(rng.uniform(1e-3, 0.1))
        v = math.sqrt(a * radius)
        if v * s.spread / radius < 0.5:       # the small-angle regime of the v²σ²/2R law
            assert circle_error(s, radius, v) == pytest.approx(SHAPER_SHARE * tol, rel=0.15)
        lim = Limits(max_velocity=10.0, max_acceleration=50.0, max_jerk=1e4)
        caps = SegmentLimits(lim, (lim, lim), jerk=False, curve_acceleration=a)
        arc = Arc((radius, 0.0), (0.0, radius), (0.0, 0.0), ccw=True)
        cap, _, _ = caps.curve_caps(arc, 10.0)
        assert cap * cap / radius == pytest.approx(min(a, 0.8 * 50.0), rel=1e-9)
    assert curve_acceleration((None, None), 1e-5) == math.inf
