"""Error metrics against brute force (dense sampling) and analytic cases."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from twin.controller.geometry import Arc, Line
from twin.controller.metrics import (
    CornerError,
    contour_error,
    coordinate_error,
    corner_error,
    cycle_time,
    overshoot,
    productivity,
    settling_travel,
    vector_error,
    velocity_error,
)
from twin.controller.spline_path import SplinePath
from twin.controller.summary import RunMetrics, summarize
from twin.errors import ConfigError

RNG = np.random.default_rng(20240611)


def mixed_path():
    """Lines, arcs (one more than half a turn) and a spline, 0.1 m scale, joined end to end."""
    segs = [Line((0.0, 0.0), (0.05, 0.0)),
            Arc((0.05, 0.0), (0.05, 0.04), (0.05, 0.02), ccw=True),
            Line((0.05, 0.04), (0.0, 0.03)),
            SplinePath([(0.0, 0.03), (-0.02, 0.05), (-0.01, 0.08), (0.03, 0.07)]),
            Arc((0.03, 0.07), (0.03 + 0.01 * math.cos(2.0), 0.06 + 0.01 * math.sin(2.0)),
                (0.03, 0.06), ccw=False)]
    for prev, seg in itertools.pairwise(segs):
        assert np.allclose(prev.end, seg.start)
    return segs


def dense(segment, spacing=2e-6):
    """Points along a segment no further than ``spacing`` apart (m)."""
    n = math.ceil(segment.length / spacing) + 1
    return segment.point(np.linspace(0.0, segment.length, n)), segment.length / (n - 1)


def brute_force_distance(path, pts):
    """Min over dense samples of every segment, and the sampling step (upper bound - h/2)."""
    best = np.full(len(pts), np.inf)
    step = 0.0
    for seg in path:
        samples, h = dense(seg)
        step = max(step, h)
        for chunk in np.array_split(np.arange(len(pts)), max(1, len(pts) // 50)):
            d = np.hypot(pts[chunk, None, 0] - samples[None, :, 0],
                         pts[chunk, None, 1] - samples[None, :, 1]).min(axis=1)
            best[chunk] = np.minimum(best[chunk], d)
    return best, step


def points_near(path, n, spread):
    """n points scattered by ``spread`` (m) about random points of the path, with their hint."""
    hint = RNG.integers(0, len(path), n)
    base = np.array([path[j].point(RNG.random() * path[j].length) for j in hint])
    return base + RNG.normal(0.0, spread, (n, 2)), hint


# -------------------------------------------------------------------- pointwise errors
def test_pointwise_errors():
    ref = RNG.normal(size=(50, 2))
    act = RNG.normal(size=(50, 2))
    np.testing.assert_array_equal(coordinate_error(ref, act), ref - act)
    np.testing.assert_allclose(vector_error(ref, act), np.linalg.norm(ref - act, axis=1),
                               rtol=1e-15)
    np.testing.assert_array_equal(velocity_error(ref, act), ref - act)


@pytest.mark.parametrize("call, message", [
    (lambda: coordinate_error(np.zeros(3), np.zeros((3, 2))), r"ref must have shape \(n, 2\)"),
    (lambda: vector_error(np.zeros((3, 2)), np.zeros((4, 2))), "actual must have 3 rows"),
    (lambda: velocity_error(np.zeros((3, 3)), np.zeros((3, 2))), r"got \(3, 3\)"),
    (lambda: contour_error([], np.zeros((3, 2))), "at least one segment"),
    (lambda: contour_error([Line((0, 0), (1, 0))], np.zeros((3, 2)), hint=[0, 0]),
     r"shape \(3,\)"),
    (lambda: contour_error([Line((0, 0), (1, 0))], np.zeros((2, 2)), hint=[0, 0], window=-1),
     "window"),
])
def test_shape_errors_name_the_input(call, message):
    with pytest.raises(ValueError, match=message):
        call()


# ----------------------------------------------------------------------- contour error
@pytest.mark.parametrize("spread", [1e-5, 3e-3])
def test_contour_error_matches_brute_force(spread):
    path = mixed_path()
    pts, _ = points_near(path, 400, spread)
    exact = contour_error(path, pts)
    brute, step = brute_force_distance(path, pts)
    assert np.all(exact <= brute + 1e-15)           # never more than a point of the path
    assert np.all(brute - exact <= step / 2 + 1e-12)  # and not less than the path allows


def test_contour_error_far_points_need_the_growing_radius():
    path = mixed_path()
    pts = RNG.uniform(-0.5, 0.5, (200, 2))  # up to metres away: many radius doublings
    brute = np.min([seg.distance(pts) for seg in path], axis=0)  # every segment, every point
    np.testing.assert_allclose(contour_error(path, pts), brute, rtol=0, atol=1e-15)


def test_contour_error_exact_cases():
    # A point at the centre of a half circle is R from it; points on the path are at 0.
    path = [Line((0.0, 0.0), (0.02, 0.0)), Arc((0.02, 0.0), (0.02, 0.02), (0.02, 0.01),
                                               ccw=True)]
    pts = np.array([[0.02, 0.01], [0.01, 0.0], [0.03, 0.01], [-0.003, 0.004]])
    np.testing.assert_allclose(contour_error(path, pts), [0.01, 0.0, 0.0, 0.005], atol=1e-15)


def test_contour_error_with_hint_equals_exact_search():
    """Near a junction the nearest segment may be the neighbour: window 0 can only be larger."""
    path = mixed_path()
    pts, hint = points_near(path, 2000, 2e-5)
    exact = contour_error(path, pts)
    for window in (1, 3):
        np.testing.assert_array_equal(contour_error(path, pts, hint=hint, window=window), exact)
    own = contour_error(path, pts, hint=hint, window=0)
    assert np.all(own >= exact) and np.any(own > exact)


def test_hint_window_limits_the_search():
    """A path that comes back near itself: the hint restricts the search to its window."""
    path = [Line((0.0, 0.0), (0.1, 0.0)), Line((0.1, 0.0), (0.1, 0.001)),
            Line((0.1, 0.001), (0.0, 0.001))]
    pts = np.array([[0.05, 0.0009]])  # on the way out, near the way back
    assert contour_error(path, pts)[0] == pytest.approx(1e-4, abs=1e-15)
    assert contour_error(path, pts, hint=[0], window=0)[0] == pytest.approx(9e-4, abs=1e-15)
    assert contour_error(path, pts, hint=[0], window=2)[0] == pytest.approx(1e-4, abs=1e-15)
    # hints outside the path are clipped to it
    assert contour_error(path, pts, hint=[-5], window=0)[0] == pytest.approx(9e-4, abs=1e-15)


def test_contour_error_of_diverged_samples_is_nan():
    path = mixed_path()
    pts = np.array([[0.01, 1e-6], [np.inf, 0.0], [np.nan, 0.0]])
    got = contour_error(path, pts)
    assert got[0] == pytest.approx(1e-6, abs=1e-15) and np.isnan(got[1:]).all()


def test_contour_error_of_no_samples():
    assert contour_error([Line((0, 0), (1, 0))], np.zeros((0, 2))).shape == (0,)


# ------------------------------------------------------------------------ corner error
def fillet_corner(alpha, r, n=20001):
    """Corner A-B-C with interior angle ``alpha`` at B = 0 and a trajectory that rounds it with
    an arc of radius r tangent to both sides, densely sampled, the bisector point included.

    The fillet's centre is on the bisector at r/sin(α/2) from B, so the closest approach to B
    is r(1/sin(α/2) − 1) and the bisector point is r(1 − sin(α/2)) from either side; the arc
    subtends π − α.
    """
    u1 = np.array([1.0, 0.0])                          # B → A
    u2 = np.array([math.cos(alpha), math.sin(alpha)])  # B → C
    a, c = 0.05 * u1, 0.05 * u2
    bisector = (u1 + u2) / np.linalg.norm(u1 + u2)
    centre = r / math.sin(alpha / 2) * bisector
    half = (math.pi - alpha) / 2
    phis = math.atan2(-bisector[1], -bisector[0]) + np.linspace(half, -half, n)  # A side first
    arc = centre + r * np.stack([np.cos(phis), np.sin(phis)], axis=1)
    feet = [centre @ u1 * u1, centre @ u2 * u2]       # tangent points
    np.testing.assert_allclose(arc[[0, -1]], feet, atol=1e-15)
    ramp = np.linspace(0.0, 1.0, 200)[:, None]
    return a, np.zeros(2), c, np.concatenate([a + ramp * (feet[0] - a), arc,
                                              feet[1] + ramp * (c - feet[1])])


@pytest.mark.parametrize("alpha_deg", [30, 60, 90, 120, 150])
@pytest.mark.parametrize("r", [1e-4, 2e-3])
def test_corner_error_of_an_arc_fillet(alpha_deg, r):
    alpha = math.radians(alpha_deg)
    a, b, c, pts = fillet_corner(alpha, r)
    res = corner_error(a, b, c, pts)
    s = math.sin(alpha / 2)
    assert res.delta_node == pytest.approx(r * (1 / s - 1), rel=1e-9)
    assert res.delta_path_max == pytest.approx(r * (1 - s), rel=1e-9)
    assert res.delta_max == res.delta_node  # 1/s − 1 ≥ 1 − s
    assert res.index == 200 + 10000  # the bisector point of the arc


def test_corner_error_of_an_overshoot_past_the_node():
    """Running e past B on a right angle: δ_B = 0, the farthest point is e from both sides."""
    e = 3e-4
    a, b, c = np.array([-0.01, 0.0]), np.zeros(2), np.array([0.0, 0.01])
    out = np.linspace(0, 1, 101)[:, None]
    pts = np.concatenate([a + out * (b - a), out * [e, 0.0], [e, 0.0] + out * ([0, 0.005] -
                                                                         np.array([e, 0.0]))])
    res = corner_error(a, b, c, pts)
    assert res == CornerError(delta_max=pytest.approx(e), delta_path_max=pytest.approx(e),
                              delta_node=0.0, index=201)


def test_corner_error_matches_dense_sampling():
    a, b, c = np.array([0.0, 0.0]), np.array([0.02, 0.0]), np.array([0.03, 0.015])
    pts = b + RNG.normal(0.0, 2e-3, (300, 2))
    ab, h1 = dense(Line(a, b))
    bc, h2 = dense(Line(b, c))
    ref = np.array([min(np.hypot(*(ab - p).T).min(), np.hypot(*(bc - p).T).min()) for p in pts])
    res = corner_error(a, b, c, pts)
    assert ref.max() - max(h1, h2) / 2 - 1e-12 <= res.delta_path_max <= ref.max() + 1e-15
    assert res.delta_node == np.hypot(*(pts - b).T).min()


# ----------------------------------------------------------- after-motion and timing
def damped(t, amplitude, sigma, omega_d):
    return amplitude * np.exp(-sigma * t) * np.sin(omega_d * t)


@pytest.mark.parametrize("sigma, omega_d", [(5.0, 2 * math.pi * 20), (40.0, 2 * math.pi * 8)])
def test_settling_travel_of_a_damped_sinusoid(sigma, omega_d):
    """Peak of A·e^(−σt)·sin(ω_d t) at tan(ω_d t*) = ω_d/σ, along a slanted direction."""
    t_end, amplitude = 0.3, 4e-6
    t = np.arange(0.0, 3.0, 1e-5)
    u = np.array([0.6, -0.8])
    target = np.array([0.1, 0.2])
    tau = np.clip(t - t_end, 0.0, None)
    pos = target + damped(tau, amplitude, sigma, omega_d)[:, None] * u
    pos[t <= t_end] = target + [0.05, 0.0] * (1 - t[t <= t_end, None] / t_end)  # the move
    t_peak = math.atan2(omega_d, sigma) / omega_d
    peak = amplitude * math.exp(-sigma * t_peak) * math.sin(omega_d * t_peak)
    assert settling_travel(t, pos, t_end, target=target) == pytest.approx(peak, rel=1e-7)
    # about the final sample (which has settled to within 1e-10 of the target)
    assert settling_travel(t, pos, t_end) == pytest.approx(peak, rel=1e-4)


def test_settling_travel_needs_samples_after_the_motion():
    with pytest.raises(ValueError, match=r"t_end = 1\.0"):
        settling_travel([0.0, 0.5, 1.0], np.zeros((3, 2)), 1.0)


@pytest.mark.parametrize("zeta", [0.1, 0.3, 0.6])
def test_overshoot_of_a_second_order_step(zeta):
    """Step response of ω²/(s² + 2ζωs + ω²): overshoot exp(−πζ/√(1−ζ²)) of the step."""
    omega, step = 2 * math.pi * 10, 0.02
    t = np.arange(0.0, 1.0, 2e-6)
    wd = omega * math.sqrt(1 - zeta**2)
    y = 1 - np.exp(-zeta * omega * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2)
                                          * np.sin(wd * t))
    u = np.array([1.0, 1.0]) / math.sqrt(2)
    start = np.array([0.01, -0.02])
    pos = start + step * y[:, None] * u
    expected = step * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    got = overshoot(t, pos, start + step * u, 5 * u)
    assert got == pytest.approx(expected, rel=1e-8)
    assert overshoot(t, pos, start + step * u, -u) == pytest.approx(step)  # before the move
    assert overshoot(t, pos, start + step * u, -u, after=0.5) < expected
    assert overshoot(t, pos, start + 2 * step * u, u) == 0.0  # never reaches


def test_cycle_time_and_productivity():
    t = np.arange(0, 20) * 0.005
    moving = np.zeros(20, dtype=bool)
    moving[3:11] = True
    moving[14] = True  # a dwell between two moves belongs to the cycle
    assert cycle_time(t, moving) == pytest.approx(12 * 0.005)
    assert cycle_time(t, np.zeros(20, dtype=bool)) == 0.0
    moving[:] = True
    assert cycle_time(t, moving) == pytest.approx(19 * 0.005)  # motion to the last sample
    assert productivity(0.03, 1.5) == pytest.approx(0.02)
    with pytest.raises(ValueError, match="duration"):
        productivity(0.03, 0.0)
    with pytest.raises(ValueError, match="path_length"):
        productivity(-1.0, 1.0)


# ---------------------------------------------------------------------------- summary
def circle_run(eps=3e-6, lag=0.0):
    """Full circle R = 10 mm at 2 mm/s, the tool on a circle of radius R + ε (1 s of rest
    after), sampled every 5 ms; optionally trailing the reference by ``lag`` rad."""
    radius, speed, T = 0.01, 0.002, 0.005
    duration = 2 * math.pi * radius / speed
    t = np.arange(0.0, duration + 1.0, T)
    phi = np.clip(t, 0.0, duration) * speed / radius
    moving = t < duration
    ref = radius * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    ref_vel = speed * np.stack([-np.sin(phi), np.cos(phi)], axis=1) * moving[:, None]
    act_phi = np.where(moving, phi - lag, phi)
    act = (radius + eps) * np.stack([np.cos(act_phi), np.sin(act_phi)], axis=1)
    act_vel = ref_vel * (radius + eps) / radius
    path = [Arc((radius, 0.0), (radius, 0.0), (0.0, 0.0), ccw=True)]
    return t, ref, ref_vel, act, act_vel, path, duration, T


def test_summarize_circle_analytic():
    eps = 3e-6
    t, ref, ref_vel, act, act_vel, path, duration, T = circle_run(eps)
    m = summarize(t, ref, ref_vel, act, act_vel, path, segment=np.zeros(len(t), dtype=int))
    assert m.samples == len(t)
    assert m.max_contour_error == pytest.approx(eps, rel=1e-6)
    assert m.rms_contour_error == pytest.approx(eps, rel=1e-6)
    assert m.max_vector_error == pytest.approx(eps, rel=1e-6)
    assert m.max_coordinate_error == pytest.approx((eps, eps), rel=1e-6)
    assert m.max_velocity_error == pytest.approx((0.002 * eps / 0.01,) * 2, rel=1e-3)
    n_moving = int(np.count_nonzero(t < duration))
    assert m.cycle_time == pytest.approx(n_moving * T)
    assert m.path_length == pytest.approx(2 * math.pi * 0.01, rel=1e-12)
    assert m.productivity == pytest.approx(m.path_length / m.cycle_time)
    assert m.settling_travel == 0.0 and m.overshoot == 0.0
    report = m.to_report()
    assert report["max_contour_error_um"] == pytest.approx(3.0, rel=1e-6)
    assert report["path_length_mm"] == pytest.approx(20 * math.pi, rel=1e-12)
    assert report["productivity_mm_per_min"] == pytest.approx(
        m.productivity * 60_000, rel=1e-12)
    assert report["max_velocity_error_x_mm_per_min"] == pytest.approx(
        m.max_velocity_error[0] * 60_000, rel=1e-12)
    assert report["cycle_time_s"] == m.cycle_time


def test_summarize_agrees_with_the_single_metrics():
    t, ref, ref_vel, act, act_vel, path, duration, _ = circle_run(eps=1e-6, lag=2e-3)
    act[-50:] += [2e-6, 0.0]  # a late disturbance after the motion
    m = summarize(t, ref, ref_vel, act, act_vel, path)
    coord = coordinate_error(ref, act)
    contour = contour_error(path, act)
    vel = velocity_error(ref_vel, act_vel)
    assert m.max_coordinate_error == tuple(np.abs(coord).max(axis=0))
    assert m.rms_coordinate_error == pytest.approx(np.sqrt((coord**2).mean(axis=0)))
    assert m.max_contour_error == contour.max()
    assert m.rms_vector_error == pytest.approx(np.sqrt((vector_error(ref, act) ** 2).mean()))
    assert m.rms_velocity_error == pytest.approx(np.sqrt((vel**2).mean(axis=0)))
    t_end = t[np.count_nonzero(t < duration)]
    assert m.settling_travel == settling_travel(t, act, t_end)
    assert m.settling_travel == pytest.approx(2e-6, rel=1e-3)
    assert set(m.to_report()) == {
        "samples", "max_coordinate_error_x_um", "max_coordinate_error_y_um",
        "rms_coordinate_error_x_um", "rms_coordinate_error_y_um", "max_contour_error_um",
        "rms_contour_error_um", "max_vector_error_um", "rms_vector_error_um",
        "max_velocity_error_x_mm_per_min", "max_velocity_error_y_mm_per_min",
        "rms_velocity_error_x_mm_per_min", "rms_velocity_error_y_mm_per_min",
        "settling_travel_um", "overshoot_um", "cycle_time_s", "path_length_mm",
        "productivity_mm_per_min"}


def test_summarize_without_rest_reports_nan_vibration():
    t, ref, ref_vel, act, act_vel, path, duration, _ = circle_run()
    keep = t < duration
    m = summarize(t[keep], ref[keep], ref_vel[keep], act[keep], act_vel[keep], path)
    assert math.isnan(m.settling_travel)


def test_run_metrics_validation_names_the_field():
    t, ref, ref_vel, act, act_vel, path, _, _ = circle_run()
    good = summarize(t, ref, ref_vel, act, act_vel, path)
    fields = {f: getattr(good, f) for f in good.__dataclass_fields__}
    with pytest.raises(ConfigError, match="max_contour_error"):
        RunMetrics(**{**fields, "max_contour_error": -1.0})
    with pytest.raises(ConfigError, match="rms_velocity_error"):
        RunMetrics(**{**fields, "rms_velocity_error": (1.0,)})
