"""Stop zones (issue 30): a circle takes the same time as a G3 arc and as the chords CAM
writes for every law, the zones never slow a contour from rest, the sampled reference keeps
the axes' limits, and arcs are cut exactly."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from twin.analysis.studies import cam
from twin.config import load_machine
from twin.controller import stop_zones
from twin.controller.gcode import parse
from twin.controller.geometry import Arc
from twin.controller.interpolator import Interpolator, InterpolatorStatus
from twin.controller.planner import PlannedBlock, Planner
from twin.controller.profiles import LAWS, Limits, min_distance
from twin.controller.profiles.laws import change_time
from twin.controller.reach import monotone_end_speed, reach_floor

LASER = load_machine("laser_belt")
FULL = not os.environ.get("CI")
PERIOD = LASER.controller.period
AXES = [LASER.axes[a].limits for a in "xy"]
BLEND_TOL = LASER.controller.contour_tolerance * LASER.controller.corner_blend      # m


def plan(text: str, law: str) -> list:
    planner = Planner.from_settings(LASER.controller, LASER.axes, law=law, work_zone=None)
    return list(planner.plan(parse(text, start=(0.01, 0.01))))


def sampled_feed_time(items: list) -> float:
    """The feed moves' time as the interpolator samples them (s): its periods from the
    first feed block's start to the last one's end at rest."""
    interp = Interpolator([b for b in items if isinstance(b, PlannedBlock) and not b.rapid],
                          period=PERIOD)
    n = 0
    while interp.update() < InterpolatorStatus.FINISHED:
        n += 1
    return n * PERIOD


def assert_limits(items: list, law: str) -> None:
    acc, jerk = cam.sampled_extremes(cam.sampled_reference(items, PERIOD), PERIOD)
    assert np.all(acc <= 1.05 * np.array([a.max_acceleration for a in AXES])), (law, acc)
    if law == "jerk-limited":
        assert np.all(jerk <= 1.05 * np.array([a.max_jerk for a in AXES])), (law, jerk)


@pytest.mark.parametrize("seed", range(40 if FULL else 3))
def test_a_chorded_circle_takes_the_g3_time_for_every_law(seed):
    """Random radius 0.5-20 mm, chord 0.001-0.5 mm (no more than 4000 chords, sagitta
    within the blend tolerance: else it is not that circle), written exactly or (a sagitta
    of 0.001 mm or more, the chordal tolerances of `twin.analysis.studies.circles`) on 3
    decimals as CAM posts write them, random law: the feed moves'
    time as the interpolator samples it within 5 % of the G3 arc's (issue 30; before the
    stop zones up to 17 % at r = 0.5 mm), the sampled time the planned one within a few
    periods, and the sampled reference within the axes' acceleration (and, jerk-limited,
    jerk) limits."""
    rng = np.random.default_rng(4000 + seed)
    r = 10 ** rng.uniform(math.log10(0.5), math.log10(20.0))
    longest = min(0.5, math.sqrt(8.0 * r * BLEND_TOL * 1e3))
    chord = max(10 ** rng.uniform(-3.0, math.log10(longest)), 2.0 * math.pi * r / 4000)
    sagitta = chord * chord / (8.0 * r)                     # the chordal tolerance (mm)
    decimals = 3 if sagitta >= 0.001 and rng.random() < 0.5 else 9
    law = LAWS[rng.integers(len(LAWS))]
    g3_items, items = plan(cam.circle(r), law), plan(
        cam.circle(r, chord=chord, decimals=decimals), law)
    g3, chorded = sampled_feed_time(g3_items), sampled_feed_time(items)
    assert abs(chorded / g3 - 1.0) <= 0.05, (law, r, chord, decimals, chorded, g3)
    planned = cam.planned_time([b for b in items if isinstance(b, PlannedBlock)], True)
    assert abs(chorded - planned) <= 3 * PERIOD, (chorded, planned)
    assert_limits(items, law)
    assert_limits(g3_items, law)


def random_contours(rng: np.random.Generator) -> str:
    """G-code: a few contours from rest to rest (G0, M3 … M5), each a chain of tangent
    arcs of random radius 0.3-20 mm and sweep, and lines, at a random feed."""
    lines = ["G21 G90 G17 G64"]
    x, y = 100.0, 100.0
    for _ in range(rng.integers(1, 4)):
        x, y = x + 40.0, y + 10.0
        lines += [f"G0 X{x:.6f} Y{y:.6f}", "M3", f"F{rng.uniform(600.0, 3000.0):.1f}"]
        heading = rng.uniform(0.0, 2.0 * math.pi)
        for _ in range(rng.integers(1, 5)):
            if rng.random() < 0.3:                # a line along the heading
                d = 10 ** rng.uniform(-2.0, 1.0)
                x, y = x + d * math.cos(heading), y + d * math.sin(heading)
                lines.append(f"G1 X{x:.9f} Y{y:.9f}")
                continue
            r = 10 ** rng.uniform(math.log10(0.3), math.log10(20.0))
            ccw = bool(rng.random() < 0.5)
            sign = 1.0 if ccw else -1.0
            cx = x - sign * r * math.sin(heading)
            cy = y + sign * r * math.cos(heading)
            sweep = rng.uniform(0.2, 2.0 * math.pi - 0.1)
            phi = math.atan2(y - cy, x - cx) + sign * sweep
            ex, ey = cx + r * math.cos(phi), cy + r * math.sin(phi)
            lines.append(f"{'G3' if ccw else 'G2'} X{ex:.9f} Y{ey:.9f} "
                         f"I{cx - x:.9f} J{cy - y:.9f}")
            x, y, heading = ex, ey, heading + sign * sweep
        lines.append("M5")
    lines.append("M2")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", range(20 if FULL else 2))
def test_the_zones_never_slow_a_contour_and_keep_the_limits(seed, monkeypatch):
    """Random contours of tangent arcs and lines between stops, every law: the planned
    time with the stop zones is no longer than without them (the reference: the same
    planner with no zone level to choose from), and the sampled reference within the
    axes' limits."""
    text = random_contours(np.random.default_rng(4100 + seed))
    for law in LAWS if FULL else ("trapezoid", "jerk-limited"):
        items = plan(text, law)
        zoned = cam.planned_time([b for b in items if isinstance(b, PlannedBlock)], True)
        with monkeypatch.context() as m:
            m.setattr(stop_zones, "FRACTIONS", ())
            plain = cam.planned_time([b for b in plan(text, law)
                                      if isinstance(b, PlannedBlock)], True)
        assert zoned <= plain * (1.0 + 1e-9), (law, zoned, plain)
        assert_limits(items, law)


@pytest.mark.parametrize("seed", range(10))
def test_an_arc_is_cut_on_its_circle(seed):
    """Random arcs (any sweep, full circles and extra turns) cut at a random distance: the
    two parts' lengths sum to the arc's, the cut point and the tangents there are the
    arc's own (its ``frame``), and the ends are the arc's."""
    rng = np.random.default_rng(4200 + seed)
    r = 10 ** rng.uniform(-4.0, -1.0)
    c = rng.uniform(-0.1, 0.1, 2)
    th0 = rng.uniform(-math.pi, math.pi)
    start = c + r * np.array([math.cos(th0), math.sin(th0)])
    full = rng.random() < 0.3
    th1 = th0 if full else th0 + rng.uniform(0.1, 6.0)
    end = c + r * np.array([math.cos(th1), math.sin(th1)])
    arc = Arc(start, end, c, ccw=bool(rng.random() < 0.5), turns=int(rng.integers(0, 3)))
    s = rng.uniform(0.01, 0.99) * arc.length
    parts = stop_zones.split_arc(arc, s)
    assert parts is not None
    a, b = parts
    assert a.length + b.length == pytest.approx(arc.length, rel=1e-12, abs=1e-15)
    assert a.length == pytest.approx(s, rel=1e-9, abs=1e-12)
    x, y, tx, ty, k, _ = arc.frame(s)
    for p, q in ((a.end, (x, y)), (b.start, (x, y)), (a.start, arc.start), (b.end, arc.end)):
        np.testing.assert_allclose(p, q, atol=1e-12)
    for part, at in ((a, a.length), (b, 0.0)):
        _, _, ux, uy, kk, _ = part.frame(at)
        np.testing.assert_allclose((ux, uy, kk), (tx, ty, k), rtol=1e-9, atol=1e-9)
    assert stop_zones.split_arc(arc, 0.0) is None and stop_zones.split_arc(arc, arc.length) \
        is None


@pytest.mark.parametrize("seed", range(10))
def test_a_zone_is_as_long_as_the_lookahead_needs_to_reach_its_cap(seed):
    """Random law, limits and speeds: the zone's length is the longest change to its cap
    from any speed between (a dense grid, brute force), and the look-ahead's monotone reach
    (`twin.controller.reach`) from the entry speed over that length gets to the cap."""
    rng = np.random.default_rng(4300 + seed)
    law = LAWS[rng.integers(len(LAWS))]
    w = rng.uniform(0.002, 0.05)
    u = w * rng.choice([0.0, rng.uniform(0.0, 0.95)])
    lim = Limits(w, rng.uniform(0.1, 2.0), rng.uniform(2.0, 100.0))
    t, d = stop_zones.zone(law, u, w, lim)
    grid = np.linspace(u, w, 20001)[:-1]
    brute = max(min_distance(law, float(x), w, lim) for x in grid)
    assert brute <= d * (1.0 + 1e-9) and d <= brute * (1.0 + 1e-6), (law, d, brute)
    assert monotone_end_speed(law, u, d * (1.0 + 1e-9), lim, reach_floor(law, d, lim)) \
        >= w * (1.0 - 1e-9)
    assert t >= change_time(law, w - u, lim)
