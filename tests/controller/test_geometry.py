"""Line, Arc and SplinePath against analytic formulas, scipy and brute force."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.interpolate import CubicSpline

from twin.controller.geometry import Arc, Line, Segment, hypot
from twin.controller.spline_path import SplinePath
from twin.errors import PlanningError

RNG_SEED = 20240611


def brute_force(seg: Segment, queries: np.ndarray, samples: int = 200_001):
    """Nearest distance to a dense sampling, and the largest gap between samples (m)."""
    pts = seg.point(np.linspace(0.0, seg.length, samples))
    gap = np.hypot(*np.diff(pts, axis=0).T).max()
    best = np.array([np.hypot(*(pts - q).T).min() for q in queries])
    return best, gap


def check_distance(seg: Segment, queries: np.ndarray) -> None:
    d = seg.distance(queries)
    s, d2 = seg.closest(queries)
    brute, gap = brute_force(seg, queries)
    assert np.all(d <= brute + 1e-12), "exact distance exceeds a sampled one"
    assert np.all(brute <= d + 0.5 * gap + 1e-12), "exact distance is far below the samples"
    np.testing.assert_array_equal(d, d2)
    # the returned arc length points at a point that is that far away
    np.testing.assert_allclose(np.hypot(*(seg.point(s) - queries).T), d, rtol=0, atol=1e-12)
    for q, dq in zip(queries[:5], d[:5], strict=False):  # scalar path agrees
        assert seg.distance(q) == pytest.approx(dq, abs=1e-15)


def query_points(seg: Segment, n: int, seed: int) -> np.ndarray:
    lo, hi = seg.bounding_box()
    pad = 0.3 * (hi - lo).max() + 1e-3
    return np.random.default_rng(seed).uniform(lo - pad, hi + pad, (n, 2))


def check_normal_offsets(seg: Segment) -> None:
    """A point moved off the path along the normal by less than the radius of curvature is
    exactly that far away (interior points only)."""
    s = np.linspace(0.05, 0.95, 37) * seg.length
    normal = seg.tangent(s) @ np.array([[0.0, 1.0], [-1.0, 0.0]])
    offset = 1e-4 * seg.length * np.linspace(-1, 1, s.size)
    d = seg.distance(seg.point(s) + offset[:, None] * normal)
    np.testing.assert_allclose(d, np.abs(offset), rtol=1e-9, atol=1e-15)


def check_bounding_box(seg: Segment) -> None:
    s = np.linspace(0.0, seg.length, 100_001)
    pts = seg.point(s)
    lo, hi = seg.bounding_box()
    assert np.all(pts >= lo - 1e-15) and np.all(pts <= hi + 1e-15)
    # a sample is within κ·δ²/8 of the extreme between its neighbours
    resolution = np.abs(seg.curvature(s)).max() * s[1] ** 2 / 8 + 1e-15
    np.testing.assert_allclose(pts.min(axis=0), lo, rtol=0, atol=resolution)
    np.testing.assert_allclose(pts.max(axis=0), hi, rtol=0, atol=resolution)


def check_scalar_matches_vector(seg: Segment) -> None:
    s = np.linspace(-0.1, 1.1, 23) * seg.length
    points, tangents, curvatures = seg.point(s), seg.tangent(s), seg.curvature(s)
    kappa_scale = 1e-12 * (1.0 + np.abs(curvatures).max())
    for i, si in enumerate(s.tolist()):
        np.testing.assert_allclose(seg.point(si), points[i], rtol=0, atol=1e-15)
        np.testing.assert_allclose(seg.tangent(si), tangents[i], rtol=0, atol=1e-14)
        assert seg.curvature(si) == pytest.approx(curvatures[i], rel=1e-12, abs=kappa_scale)
        frame = seg.frame(si)
        assert all(type(v) is float for v in frame)
        np.testing.assert_allclose(frame[:2], points[i], rtol=0, atol=1e-15)
        np.testing.assert_allclose(frame[2:4], tangents[i], rtol=0, atol=1e-14)
        assert frame[4] == pytest.approx(curvatures[i], rel=1e-12, abs=kappa_scale)
    assert seg.frame(0.0)[:2] == tuple(seg.start.tolist())
    assert seg.frame(seg.length)[:2] == tuple(seg.end.tolist())
    assert points.shape == (s.size, 2) and curvatures.shape == (s.size,)
    np.testing.assert_array_equal(seg.point(0.0), seg.start)
    np.testing.assert_array_equal(seg.point(seg.length), seg.end)
    np.testing.assert_array_equal(points[[0, -1]], [seg.start, seg.end])  # clipped
    np.testing.assert_allclose(np.hypot(*tangents.T), 1.0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(seg.start_tangent, tangents[0], atol=1e-14)
    np.testing.assert_allclose(seg.end_tangent, tangents[-1], atol=1e-14)


def check_arc_length_parameterisation(seg: Segment, s: np.ndarray, h: float) -> None:
    """|dP/ds| = 1 and dP/ds = tangent and dT/ds = κ·N by central differences at s (each
    at least h from a knot, where the derivative of curvature may jump)."""
    dp = (seg.point(s + h) - seg.point(s - h)) / (2 * h)
    kappa = seg.curvature(s)
    # a chord of a curve of curvature κ is shorter than the arc by κ²h²/6 (relative)
    np.testing.assert_allclose(np.hypot(*dp.T), 1.0 - kappa**2 * h**2 / 6, rtol=0, atol=1e-8)
    np.testing.assert_allclose(dp, seg.tangent(s), rtol=0, atol=1e-8 + (kappa**2).max() * h**2)
    dt = (seg.tangent(s + h) - seg.tangent(s - h)) / (2 * h)
    normal = seg.tangent(s) @ np.array([[0.0, 1.0], [-1.0, 0.0]])
    np.testing.assert_allclose((dt * normal).sum(axis=1), kappa, rtol=1e-5,
                               atol=1e-6 * np.abs(kappa).max() + 1e-9)
    rate = np.array([seg.frame(si)[5] for si in s.tolist()])
    dk = (seg.curvature(s + h) - seg.curvature(s - h)) / (2 * h)
    np.testing.assert_allclose(rate, dk, rtol=1e-4, atol=1e-6 * np.abs(dk).max() + 1e-9)


# -- Line -----------------------------------------------------------------------------------

LINES = [((0.0, 0.0), (0.3, 0.4)), ((1.0, -2.0), (-0.5, -2.0)), ((1e-3, 2e-3), (1e-3, -7e-3)),
         ((0.1, 0.1), (0.1 + 1e-7, 0.1 - 3e-7))]


@pytest.mark.parametrize(("start", "end"), LINES)
def test_line_against_analytic_formulas(start, end):
    seg = Line(start, end)
    a, b = np.array(start), np.array(end)
    length = math.dist(start, end)
    assert seg.length == pytest.approx(length, rel=1e-15)
    s = np.linspace(0.0, length, 11)
    u = (b - a) / length
    np.testing.assert_allclose(seg.point(s), a + s[:, None] * u, rtol=0, atol=1e-15)
    np.testing.assert_allclose(seg.tangent(s), np.tile(u, (11, 1)), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(seg.curvature(s), 0.0)
    check_scalar_matches_vector(seg)


@pytest.mark.parametrize(("start", "end"), LINES)
def test_line_distance_is_exact(start, end):
    seg = Line(start, end)
    check_distance(seg, query_points(seg, 60, seed=1))
    check_normal_offsets(seg)
    check_bounding_box(seg)
    # beyond the ends the distance is to the end point
    beyond = seg.end + 2.0 * seg.length * seg.end_tangent
    assert seg.closest(beyond) == (seg.length, pytest.approx(2.0 * seg.length, rel=1e-14))


def test_line_of_zero_length_is_rejected():
    with pytest.raises(PlanningError, match="zero length"):
        Line((1.0, 2.0), (1.0, 2.0))
    with pytest.raises(PlanningError, match="end must be a finite point"):
        Line((0.0, 0.0), (np.nan, 1.0))


# -- Arc ------------------------------------------------------------------------------------

# start, end, center, ccw, turns, expected sweep (rad)
ARCS = [
    ((1.0, 0.0), (0.0, 1.0), (0.0, 0.0), True, 0, math.pi / 2),
    ((1.0, 0.0), (0.0, 1.0), (0.0, 0.0), False, 0, -3 * math.pi / 2),
    ((0.0, 1.0), (1.0, 0.0), (0.0, 0.0), False, 0, -math.pi / 2),
    ((0.012, 0.0), (-0.008, 0.0), (0.002, 0.0), True, 0, math.pi),
    ((0.012, 0.0), (-0.008, 0.0), (0.002, 0.0), False, 0, -math.pi),
    ((0.5, 0.2), (0.5, 0.2), (0.3, 0.2), True, 0, 2 * math.pi),
    ((0.5, 0.2), (0.5, 0.2), (0.3, 0.2), False, 0, -2 * math.pi),
    ((0.5, 0.2), (0.5, 0.2), (0.3, 0.2), True, 2, 6 * math.pi),
    ((1.0, 0.0), (0.0, 1.0), (0.0, 0.0), True, 1, 2.5 * math.pi),
    ((-0.02, 0.03), (0.04, 0.03), (0.01, -0.01), False, 0, -2 * math.atan2(0.03, 0.04)),
]


@pytest.mark.parametrize(("start", "end", "center", "ccw", "turns", "sweep"), ARCS)
def test_arc_against_analytic_formulas(start, end, center, ccw, turns, sweep):
    seg = Arc(start, end, center, ccw=ccw, turns=turns)
    r = math.dist(start, center)
    assert seg.radius == pytest.approx(r, rel=1e-15)
    assert seg.sweep == pytest.approx(sweep, rel=1e-14)
    assert seg.length == pytest.approx(r * abs(sweep), rel=1e-14)
    theta0 = math.atan2(start[1] - center[1], start[0] - center[0])
    s = np.linspace(0.0, seg.length, 17)
    phi = theta0 + np.sign(sweep) * s / r
    expected = np.array(center) + r * np.stack((np.cos(phi), np.sin(phi)), axis=1)
    np.testing.assert_allclose(seg.point(s), expected, rtol=0, atol=1e-15 * (1 + r) * 4)
    direction = np.sign(sweep) * np.stack((-np.sin(phi), np.cos(phi)), axis=1)
    np.testing.assert_allclose(seg.tangent(s), direction, rtol=0, atol=1e-14)
    np.testing.assert_allclose(seg.curvature(s), np.sign(sweep) / r, rtol=1e-15)
    check_scalar_matches_vector(seg)
    s = np.linspace(0.01, 0.99, 301) * seg.length
    check_arc_length_parameterisation(seg, s, h=1e-4 * r)


def test_arc_end_tangents_are_those_of_frame_bit_for_bit():
    """The planner takes a block's end tangents from ``end_tangents`` instead of two calls
    of ``frame``: they must be the same floats, or plans would depend on the path taken."""
    rng = np.random.default_rng(11)
    for start, end, center, ccw, turns, _ in ARCS:
        seg = Arc(start, end, center, ccw=ccw, turns=turns)
        f0, f1 = seg.frame(0.0), seg.frame(seg.length)
        assert seg.end_tangents() == (f0[2], f0[3], f1[2], f1[3])
    for _ in range(2000):
        c, r = rng.normal(size=2), rng.uniform(1e-4, 3.0)
        a0, a1 = rng.uniform(-7.0, 7.0, 2)
        seg = Arc(c + r * np.array([math.cos(a0), math.sin(a0)]),
                  c + r * np.array([math.cos(a1), math.sin(a1)]), c,
                  ccw=bool(rng.integers(2)), tol=1e-6)
        f0, f1 = seg.frame(0.0), seg.frame(seg.length)
        assert seg.end_tangents() == (f0[2], f0[3], f1[2], f1[3])


def test_arc_midpoints_of_the_two_directions():
    ccw = Arc((1.0, 0.0), (0.0, 1.0), (0.0, 0.0), ccw=True)
    cw = Arc((1.0, 0.0), (0.0, 1.0), (0.0, 0.0), ccw=False)
    h = math.sqrt(0.5)
    np.testing.assert_allclose(ccw.point(ccw.length / 2), [h, h], atol=1e-15)
    np.testing.assert_allclose(cw.point(cw.length / 2), [-h, -h], atol=1e-15)
    np.testing.assert_allclose(ccw.start_tangent, [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(cw.start_tangent, [0.0, -1.0], atol=1e-15)
    np.testing.assert_allclose(cw.end_tangent, [1.0, 0.0], atol=1e-15)


@pytest.mark.parametrize(("start", "end", "center", "ccw", "turns", "sweep"), ARCS)
def test_arc_distance_is_exact(start, end, center, ccw, turns, sweep):
    seg = Arc(start, end, center, ccw=ccw, turns=turns)
    queries = np.vstack((query_points(seg, 40, seed=2), [center]))
    d = seg.distance(queries)
    assert d[-1] == pytest.approx(seg.radius, rel=1e-15)  # the centre is r from every point
    if abs(sweep) < 2 * math.pi:
        check_distance(seg, queries)
    else:  # a full circle revisits points: compare distances only
        brute, gap = brute_force(seg, queries, samples=100_001)
        assert np.all(d <= brute + 1e-12) and np.all(brute <= d + 0.5 * gap + 1e-12)
        s, _ = seg.closest(queries)
        assert np.all(s < 2 * math.pi * seg.radius)  # the first pass
    check_normal_offsets(seg)
    check_bounding_box(seg)


@given(st.floats(-math.pi, math.pi), st.floats(0.01, 6.2), st.booleans(),
       st.floats(-1.0, 1.0), st.floats(-1.0, 1.0))
def test_arc_distance_property(theta0, span, ccw, qx, qy):
    r = 0.02
    theta1 = theta0 + (span if ccw else -span)
    start = (r * math.cos(theta0), r * math.sin(theta0))
    end = (r * math.cos(theta1), r * math.sin(theta1))
    seg = Arc(start, end, (0.0, 0.0), ccw=ccw, tol=1e-15)
    assert seg.length == pytest.approx(r * span, rel=1e-9, abs=1e-15)
    q = np.array([qx, qy]) * 2 * r
    s, d = seg.closest(q)
    # exact answer: the angle of q inside the swept range → |ρ − r|, else the nearer end
    rho, phi = math.hypot(*q), math.atan2(q[1], q[0])
    offset = ((phi - theta0) * (1 if ccw else -1)) % (2 * math.pi)
    expected = abs(rho - r) if offset <= span else min(math.dist(q, start), math.dist(q, end))
    assert d == pytest.approx(expected, rel=1e-9, abs=1e-15)
    assert math.dist(seg.point(s), q) == pytest.approx(d, rel=1e-9, abs=1e-15)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"start": (1.0, 0.0), "end": (0.0, 1.001), "center": (0.0, 0.0), "ccw": True},
         "arc end point is not on the circle"),
        ({"start": (0.0, 0.0), "end": (0.0, 0.0), "center": (0.0, 0.0), "ccw": True},
         "zero radius"),
        ({"start": (1.0, 0.0), "end": (0.0, 1.0), "center": (0.0, 0.0), "ccw": 1},
         "ccw must be a bool"),
        ({"start": (1.0, 0.0), "end": (0.0, 1.0), "center": (0.0, 0.0), "ccw": True,
          "turns": -1}, "turns must be an integer"),
        ({"start": (1.0, 0.0), "end": (0.0, 1.0), "center": (0.0, 0.0), "ccw": True,
          "tol": -1.0}, "tol must be finite"),
        ({"start": (1.0, 0.0), "end": (0.0, 1.0), "center": (0.0, np.inf), "ccw": True},
         "center must be a finite point"),
    ],
)
def test_arc_validation(kwargs, message):
    with pytest.raises(PlanningError, match=message):
        Arc(**kwargs)
    with pytest.raises(ValueError, match=message):  # PlanningError is a ValueError
        Arc(**kwargs)


def test_arc_end_tolerance_is_honoured():
    off = (0.0, 1.0 + 5e-7)
    with pytest.raises(PlanningError):
        Arc((1.0, 0.0), off, (0.0, 0.0), ccw=True)
    seg = Arc((1.0, 0.0), off, (0.0, 0.0), ccw=True, tol=1e-6)
    np.testing.assert_array_equal(seg.point(seg.length), off)  # ends on the programmed point


# -- SplinePath -----------------------------------------------------------------------------

def wavy_points(n: int, seed: int, scale: float = 0.05) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angle = np.cumsum(rng.uniform(-1.0, 1.0, n))
    step = rng.uniform(0.2, 1.0, n)
    pts = np.cumsum(np.stack((step * np.cos(angle), step * np.sin(angle)), 1), axis=0)
    return scale * pts / step.sum()


SPLINES = {
    "wavy": wavy_points(25, 1),
    "tiny": wavy_points(12, 2, scale=1e-4),
    "long": wavy_points(300, 3, scale=1.0),
    "circle": 0.01 * np.stack((np.cos(np.linspace(0, 5.5, 14)), np.sin(np.linspace(0, 5.5, 14))),
                              axis=1),
    "three": np.array([[0.0, 0.0], [0.01, 0.02], [0.03, 0.0]]),
}


def scipy_reference(pts: np.ndarray):
    """The same parametric spline from scipy, with its arc length at each knot by quad."""
    u = np.r_[0.0, np.cumsum(np.hypot(*np.diff(pts, axis=0).T))]
    curve = CubicSpline(u, pts, bc_type="natural")
    vel = curve.derivative()

    def speed(t: float) -> float:
        return float(np.hypot(*vel(t)))

    lengths = [quad(speed, a, b, epsabs=0, epsrel=1e-13, limit=200)[0]
               for a, b in itertools.pairwise(u)]
    return u, curve, speed, np.r_[0.0, np.cumsum(lengths)]


@pytest.mark.parametrize("name", SPLINES)
def test_spline_length_and_knots_against_scipy_quadrature(name):
    pts = SPLINES[name]
    seg = SplinePath(pts)
    _, _, _, knot_s = scipy_reference(pts)
    assert seg.pieces == len(pts) - 1
    np.testing.assert_allclose(seg.knot_s, knot_s, rtol=1e-12, atol=0)
    assert seg.length == pytest.approx(knot_s[-1], rel=1e-12)
    np.testing.assert_allclose(seg.point(seg.knot_s), pts, rtol=0, atol=1e-13 * seg.length)
    # the dense polyline is shorter, by Σ κ²δ³/24 to leading order
    s = np.linspace(0, seg.length, 100_001)
    poly = np.hypot(*np.diff(seg.point(s), axis=0).T).sum()
    deficit = (seg.curvature(s[:-1] + 0.5 * s[1]) ** 2).sum() * s[1] ** 3 / 24
    assert seg.length - poly == pytest.approx(deficit, rel=1e-3, abs=1e-14 * seg.length)


@pytest.mark.parametrize("name", SPLINES)
def test_spline_arc_length_inverse_against_scipy(name):
    """point(s(u)) must be the scipy curve at u, with s(u) integrated by scipy.quad."""
    pts = SPLINES[name]
    seg = SplinePath(pts, method="blocks4")
    u, curve, speed, knot_s = scipy_reference(pts)
    uq = np.random.default_rng(4).uniform(0, u[-1], 40)
    k = np.searchsorted(u, uq, side="right") - 1
    s = np.array([knot_s[i] + quad(speed, u[i], x, epsabs=0, epsrel=1e-13)[0]
                  for i, x in zip(k, uq, strict=True)])
    np.testing.assert_allclose(seg.point(s), curve(uq), rtol=0, atol=1e-12 * seg.length)
    tangent = curve(uq, 1) / np.hypot(*curve(uq, 1).T)[:, None]
    np.testing.assert_allclose(seg.tangent(s), tangent, rtol=0, atol=1e-10)
    d1, d2 = curve(uq, 1), curve(uq, 2)
    kappa = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.hypot(*d1.T) ** 3
    np.testing.assert_allclose(seg.curvature(s), kappa, rtol=1e-9, atol=1e-9 / seg.length)
    # dκ/ds from scipy's third derivative
    d3 = curve(uq, 3)
    speed2 = (d1**2).sum(axis=1)
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    dkdt = ((d1[:, 0] * d3[:, 1] - d1[:, 1] * d3[:, 0]) / speed2**1.5
            - 3 * cross * (d1 * d2).sum(axis=1) / speed2**2.5)
    rate = np.array([seg.frame(si)[5] for si in s.tolist()])
    np.testing.assert_allclose(rate, dkdt / np.sqrt(speed2), rtol=1e-8,
                               atol=1e-9 * np.abs(dkdt).max())
    for si, pi in zip(s[:10].tolist(), curve(uq[:10]), strict=True):  # scalar path
        np.testing.assert_allclose(seg.point(si), pi, rtol=0, atol=1e-12 * seg.length)


@pytest.mark.parametrize("name", SPLINES)
def test_spline_is_arc_length_parameterised(name):
    seg = SplinePath(SPLINES[name])
    check_scalar_matches_vector(seg)
    fractions = np.array([0.1, 0.3, 0.5, 0.7, 0.9])
    s = (seg.knot_s[:-1, None] + np.diff(seg.knot_s)[:, None] * fractions).ravel()
    check_arc_length_parameterisation(seg, s, h=1e-3 * np.diff(seg.knot_s).min())


@pytest.mark.parametrize("name", SPLINES)
def test_spline_distance_is_exact(name):
    seg = SplinePath(SPLINES[name])
    queries = np.vstack((query_points(seg, 40, seed=5), SPLINES[name][3:5] + 1e-9))
    check_distance(seg, queries)
    check_normal_offsets(seg)
    check_bounding_box(seg)


def test_straight_spline_distance_matches_the_line():
    """Collinear points: the spline is the line and its quintic degenerates."""
    line = Line((0.01, -0.02), (0.05, 0.01))
    seg = SplinePath(line.point(np.array([0.0, 0.003, 0.011, 0.02, 0.05])))
    assert seg.length == pytest.approx(line.length, rel=1e-13)
    queries = query_points(line, 200, seed=6)
    np.testing.assert_allclose(seg.distance(queries), line.distance(queries), rtol=0,
                               atol=1e-12)
    s = np.linspace(0, line.length, 50)
    np.testing.assert_allclose(seg.point(s), line.point(s), rtol=0, atol=1e-14)
    np.testing.assert_allclose(seg.curvature(s), 0.0, atol=1e-9)


def test_two_point_spline_is_a_line():
    seg = SplinePath([(0.0, 0.0), (0.03, 0.04)])
    assert seg.length == pytest.approx(0.05, rel=1e-15)
    np.testing.assert_allclose(seg.point(0.025), [0.015, 0.02], atol=1e-16)
    assert seg.curvature(0.01) == 0.0


@pytest.mark.parametrize(
    ("points", "message"),
    [
        ([(0.0, 0.0)], r"shape \(n ≥ 2, 2\)"),
        ([(0.0, 0.0, 0.0), (1.0, 1.0, 1.0)], r"shape \(n ≥ 2, 2\)"),
        ([(0.0, 0.0), (1.0, 1.0), (1.0, 1.0)], r"points\[2\] repeats points\[1\]"),
        ([(0.0, 0.0), (np.nan, 1.0)], r"points\[1\] is not finite"),
    ],
)
def test_spline_validation(points, message):
    with pytest.raises(PlanningError, match=message):
        SplinePath(points)


def test_query_shape_is_checked():
    with pytest.raises(ValueError, match=r"shape \(2,\) or \(n, 2\)"):
        Line((0, 0), (1, 0)).distance(np.zeros((3, 3)))


def test_compiled_hypot_is_pythons_bit_for_bit():
    """geometry.hypot (compiled, for the blender's corners) against CPython's math.hypot:
    the same double on random pairs over 30 decades, near-equal and zero legs, subnormals
    and the overflow range (the C library's hypot differs in the last bit now and then)."""
    rng = np.random.default_rng(RNG_SEED)
    n = 20_000
    x = rng.normal(size=n) * 10.0 ** rng.integers(-15, 15, n)
    y = rng.normal(size=n) * 10.0 ** rng.integers(-15, 15, n)
    y[::4] = x[::4] * rng.uniform(0.999, 1.001, len(x[::4]))
    y[::9] = 0.0
    pairs = [*zip(x.tolist(), y.tolist(), strict=True), (5e-324, 5e-324), (1e-310, -3e-310),
             (1e308, 1e308), (-0.0, 0.0), (3.0, 4.0), (math.inf, math.nan), (math.nan, 1.0)]
    for a, b in pairs:
        want, got = math.hypot(a, b), hypot(a, b)
        assert got == want or (math.isnan(got) and math.isnan(want)), (a, b)
