"""Corner blending, chords planned as the curves they approximate, smooth laws across blocks,
and the limits of the planned reference (issue 12)."""

from __future__ import annotations

import dataclasses
import itertools
import math
import os

import numpy as np
import pytest

from twin.analysis.studies import cam
from twin.config import load_machine
from twin.controller.blend import BlendedBlock, Blender, blend_radius
from twin.controller.controller import Controller
from twin.controller.gcode import parse
from twin.controller.geometry import Arc, Line
from twin.controller.interpolator import Interpolator, InterpolatorStatus
from twin.controller.loop_defaults import default_corner_model
from twin.controller.planner import PlannedBlock, Planner
from twin.controller.profiles import LAWS

LASER = load_machine("laser_belt")
TOMSK = load_machine("tomsk_xy")
FULL = not os.environ.get("CI")


def planner(cfg=LASER, **options):
    options.setdefault("work_zone", None)
    return Planner.from_settings(cfg.controller, cfg.axes, **options)


def planned(text, cfg=LASER, **options):
    return [b for b in planner(cfg, **options).plan(parse(text, start=(0.01, 0.01)))
            if isinstance(b, PlannedBlock)]


# ------------------------------------------------------------------------ geometry
@pytest.mark.parametrize("seed", range(30))
def test_a_blend_is_tangent_to_both_lines_and_within_the_tolerance(seed):
    rng = np.random.default_rng(seed)
    v = rng.uniform(0.05, 0.15, 2)
    a = v - rng.uniform(1e-4, 5e-3) * np.array([math.cos(h := rng.uniform(0, 6.3)),
                                                 math.sin(h)])
    turn = rng.uniform(0.01, 3.0) * rng.choice([-1, 1])
    out_dir = (v - a) / np.linalg.norm(v - a)
    c, s = math.cos(turn), math.sin(turn)
    out_dir = np.array([c * out_dir[0] - s * out_dir[1], s * out_dir[0] + c * out_dir[1]])
    b = v + rng.uniform(1e-4, 5e-3) * out_dir
    tol = rng.uniform(1e-6, 1e-4)
    out = list(Blender(tol).blend([(Line(a, v), 0.01, 1), (Line(v, b), 0.02, 2)]))
    segs = [o.segment for o in out]
    arcs = [o for o in out if o.blend]
    assert len(arcs) == 1 and isinstance(arcs[0].segment, Arc)
    arc = arcs[0].segment
    assert arcs[0].feed == 0.01 and arcs[0].line == 2
    for first, second in itertools.pairwise(segs):         # continuous and tangent
        assert np.array_equal(first.end, second.start)
        np.testing.assert_allclose(first.end_tangent, second.start_tangent, atol=1e-9)
    assert np.array_equal(segs[0].start, a) and np.array_equal(segs[-1].end, b)
    # the arc stays within the tolerance of the corner, and no closer than it needs
    gap = float(np.min(np.hypot(*(arc.point(np.linspace(0, arc.length, 2001)) - v).T)))
    angle = abs(turn)
    expected = blend_radius(angle, min(np.linalg.norm(v - a), np.linalg.norm(b - v)) / 2, tol)
    assert arc.radius == pytest.approx(expected, rel=1e-9)
    assert gap == pytest.approx(arc.radius * (1 / math.cos(angle / 2) - 1), rel=1e-6, abs=1e-12)
    assert gap <= tol * (1 + 1e-9)


def test_blends_of_a_chorded_circle_meet_at_the_chords_and_have_its_radius():
    r = 2e-3
    n = 25
    pts = [(r * math.cos(2 * math.pi * k / n), r * math.sin(2 * math.pi * k / n))
           for k in range(n + 1)]
    trip = [(Line(pts[k], pts[k + 1]), 0.05, k + 1) for k in range(n)]
    out = list(Blender(25e-6).blend(trip))
    arcs = [o.segment for o in out if o.blend]
    assert len(arcs) == n - 1                         # every node, none at the open ends
    half = math.pi / n                                # half the deflection
    for arc in arcs:
        assert arc.radius == pytest.approx(r * math.cos(half), rel=1e-9)
    lines = [o.segment for o in out if not o.blend]
    assert len(lines) == 2                            # only the half chords at the ends


def test_barriers_rapids_and_arcs_are_not_blended():
    a, b, c = (0.0, 0.0), (0.01, 0.0), (0.01, 0.01)
    arc = Arc(c, (0.02, 0.02), (0.02, 0.01), ccw=False)
    marker = object()
    out = list(Blender(1e-5).blend([(Line(a, b), 0.01, 1), marker, (Line(b, c), 0.01, 2),
                                    (arc, 0.01, 3), (Line((0.02, 0.02), (0.03, 0.03)), None, 4)]))
    assert [o if o is marker else type(o.segment).__name__ for o in out] == [
        "Line", marker, "Line", "Arc", "Line"]
    assert not any(isinstance(o, BlendedBlock) and o.blend for o in out)


# ------------------------------------------------------------------------ one corner model
def test_the_planner_and_the_controller_use_one_corner_model():
    for cfg in (TOMSK, LASER):
        ctrl = Controller.from_machine(cfg, None)
        assert Planner.from_settings(cfg.controller, cfg.axes).corner_model == \
            ctrl.planner.corner_model == default_corner_model(cfg.controller, cfg.axes)


# ------------------------------------------------------------------------ chords as curves
def mid_circle_speed(text, law):
    return cam.middle_speed(planned(text, law=law))


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("radius", [2.0, 20.0])
def test_a_circle_runs_at_the_same_speed_whatever_its_chords(radius, law):
    """G3 and chords of 0.5, 0.1, 0.01 (and in the full run 0.001) mm: within 5 %."""
    chords = [0.5, 0.1, 0.01] + ([0.001] if FULL else [])
    speeds = [mid_circle_speed(cam.circle(radius), law)]
    speeds += [mid_circle_speed(cam.circle(radius, chord=c), law) for c in chords]
    assert max(speeds) <= 1.05 * min(speeds), [round(v * 1e3, 3) for v in speeds]
    if radius == 2.0:            # the centripetal cap binds, not the 50 mm/s feed
        assert max(speeds) < 0.045


# ------------------------------------------------------------------------ limits held
PROGRAMS = {"lettering": lambda: cam.lettering("XY-26" if FULL else "XY", height=30.0),
            "pocket": lambda: cam.pocket(60.0, 40.0),
            "nest": lambda: cam.chorded_nest(2, 1) if FULL else cam.chorded_nest(1, 1)}


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("program", PROGRAMS)
def test_the_planned_reference_keeps_every_axis_within_its_acceleration(program, law):
    items = list(planner(law=law).plan(parse(PROGRAMS[program](), start=(0.01, 0.01))))
    acc = cam.sampled_acceleration(items, LASER.controller.period)
    limits = np.array([LASER.axes[a].limits.max_acceleration for a in "xy"])
    assert np.all(acc <= 1.05 * limits), acc / limits


# ------------------------------------------------------------------------ smooth laws
@pytest.mark.parametrize("law", [law for law in LAWS if law != "trapezoid"])
def test_a_smooth_law_accelerates_across_the_nodes_of_short_blocks(law):
    """A 20 mm line sent as 400 chords of 0.05 mm: one speed change over many blocks, not a
    change inside each block (the whole line as one block is the reference)."""
    n = 400
    text = "G21 G90 G0 X10 Y10\nF3000\n" + "\n".join(
        f"G1 X{10 + 20 * (k + 1) / n:.4f} Y10" for k in range(n)) + "\nM2\n"
    chords = [b for b in planned(text, law=law) if not b.rapid]
    whole = [b for b in planned("G21 G90 G0 X10 Y10\nG1 X30 F3000\nM2\n", law=law)
             if not b.rapid]
    t_chords = sum(b.profile().duration for b in chords)
    t_whole = sum(b.profile().duration for b in whole)
    assert t_chords <= 1.01 * t_whole
    # blocks that start or end mid-change: the acceleration runs on across their nodes
    moving = [b for b in chords if abs(b.profile().at(0.0)[2]) > 0.1]
    assert len(moving) > 10
    # and the law's limits hold across them: sampled acceleration and jerk
    period = LASER.controller.period
    interp = Interpolator(chords, period=period)
    acc = [interp.reference.acceleration.copy()]
    while interp.update() < InterpolatorStatus.FINISHED:
        acc.append(interp.reference.acceleration.copy())
    acc = np.array(acc)
    contour = LASER.controller.limits
    assert np.abs(acc).max() <= contour.max_acceleration * (1 + 1e-9)
    assert np.abs(np.diff(acc, axis=0)).max() / period <= contour.max_jerk * 1.001


def test_a_calibrated_corner_constant_changes_nothing_on_chorded_programs():
    """Chords are blended, so no kink is left for the corner model: a constant fitted to
    one sharp corner (seed 001's c = 0.213, six times less cautious than the default)
    plans a chorded job exactly as the default does, never faster and less safe."""
    default = planner().corner_model
    calibrated = dataclasses.replace(default, calibration=0.213)
    text = cam.chorded_nest(1, 1)
    one = [(b.v_start, b.v_end) for b in planned(text)]
    two = [(b.v_start, b.v_end) for b in planned(text, corner_model=calibrated)]
    assert one == two


# ------------------------------------------------------------------------ path control
SQUARE = "G21 G90 F3000\nG1 X20 Y10\nG1 X30 Y10\nG1 X30 Y20\nG1 X20 Y20\nG1 X20 Y10\nM2"


@pytest.mark.parametrize(("header", "blends", "stops"), [
    ("", 3, 0),                   # G64 at power-on: the machine's blend tolerance
    ("G61", 0, 0),                # exact path: sharp corners, passed at speed
    ("G61.1", 0, 4),              # exact stop: at rest at every node, the straight one too
    ("G64 P0.05", 3, 0),          # a program's own tolerance
    ("G64 P0", 3, 0),             # P0 is plain G64
])
def test_a_programs_path_control_sets_rounding_and_stops(header, blends, stops):
    text = SQUARE.replace("F3000", f"F3000 {header}")
    blocks = planned(text)
    assert sum(b.blend for b in blocks) == blends
    inner = blocks[:-1]
    assert sum(b.v_end == 0.0 for b in inner) == stops
    if header == "G61":
        assert all(b.v_end > 0.0 for b in inner)


def test_g64_p_is_the_largest_deviation_of_a_rounded_corner():
    def deviation(text):
        arcs = [b.segment for b in planned(text) if b.blend]
        corner = np.array([0.030, 0.010])
        # the distance of a blend arc's midpoint from the vertex it rounds, less the
        # distance of the arc from the vertex along the bisector (= the deviation)
        arc = min(arcs, key=lambda a: np.linalg.norm(np.asarray(a.center) - corner))
        return np.linalg.norm(corner - np.asarray(arc.center)) - arc.radius

    wide = deviation(SQUARE.replace("F3000", "F3000 G64 P0.05"))
    narrow = deviation(SQUARE.replace("F3000", "F3000 G64 P0.001"))
    assert wide == pytest.approx(0.05e-3, rel=1e-6)
    assert narrow == pytest.approx(0.001e-3, rel=1e-6)
