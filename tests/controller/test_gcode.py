"""The G-code reader on valid programs: exact items in SI, modes, units, arcs, events."""

from __future__ import annotations

import cmath
import doctest
import itertools
import math

import numpy as np
import pytest

import twin.controller.gcode as gcode_pkg
from twin.controller.gcode import (
    ArcTolerance,
    Dwell,
    Event,
    Interpreter,
    Move,
    ProgramEnd,
    parse,
)
from twin.controller.gcode import arcs as arcs_module
from twin.controller.gcode import interpreter as interpreter_module
from twin.controller.gcode.lexer import lex
from twin.errors import ConfigError, GCodeError

MM = 1e-3
INCH = 25.4e-3
MM_PER_MIN = 1e-3 / 60.0


def approx_point(x_mm: float, y_mm: float, unit: float = MM):
    return pytest.approx((x_mm * unit, y_mm * unit), abs=1e-12)


# -- lines and rapids -----------------------------------------------------------------------

LINE_CASES = [
    # (program, [(kind, start mm, end mm, feed mm/min or None)])
    ("G0 X10 Y5", [("rapid", (0, 0), (10, 5), None)]),
    ("G1 X10 F600\nY20\nX0 Y0",
     [("line", (0, 0), (10, 0), 600), ("line", (10, 0), (10, 20), 600),
      ("line", (10, 20), (0, 0), 600)]),
    ("G91 G1 X10 F600\nY20\nX-10 Y-20",
     [("line", (0, 0), (10, 0), 600), ("line", (10, 0), (10, 20), 600),
      ("line", (10, 20), (0, 0), 600)]),
    ("G0 X1\nG1 X2 F100\nG0 X3\nX4\nG1 X5",
     [("rapid", (0, 0), (1, 0), None), ("line", (1, 0), (2, 0), 100),
      ("rapid", (2, 0), (3, 0), None), ("rapid", (3, 0), (4, 0), None),
      ("line", (4, 0), (5, 0), 100)]),
    # G90/G91 act on their own block; zero-length moves yield nothing
    ("G0 X5 Y5\nG91 X1\nG90 X1\nX1\nG1 F50 X1 Y5",
     [("rapid", (0, 0), (5, 5), None), ("rapid", (5, 5), (6, 5), None),
      ("rapid", (6, 5), (1, 5), None)]),
    # case, spaces inside words (RS-274/NGC), leading zeros, "1." and ".5" forms
    ("g 0 1 x 1 0 . 5 y-.5 f 1 2 0 0.", [("line", (0, 0), (10.5, -0.5), 1200)]),
    # comments of both kinds, block delete, N words, G80 then a new mode
    ("N10 (rapid) G0 X1 ; to x = 1\n/N20 G1 X2 F10 (slow)\nG80\nG0 Y1",
     [("rapid", (0, 0), (1, 0), None), ("line", (1, 0), (2, 0), 10),
      ("rapid", (2, 0), (2, 1), None)]),
    # CAM header of states this machine is always in
    ("G17 G21 G40 G49 G54 G80 G90 G94\nG0 X1", [("rapid", (0, 0), (1, 0), None)]),
]


@pytest.mark.parametrize(("text", "expected"), LINE_CASES)
def test_lines_and_rapids_are_exact_si(text, expected):
    moves = parse(text).moves
    assert [m.kind for m in moves] == [e[0] for e in expected]
    for move, (_kind, start, end, feed) in zip(moves, expected, strict=True):
        assert move.start == approx_point(*start)
        assert move.end == approx_point(*end)
        if feed is None:
            assert move.feed is None
        else:
            assert move.feed == pytest.approx(feed * MM_PER_MIN, rel=1e-15)
        assert move.center is None and move.turns == 0


def test_incremental_and_absolute_programs_give_the_same_moves():
    rng = np.random.default_rng(7)
    points = np.round(rng.uniform(-50, 50, size=(40, 2)), 3)
    absolute = ["G90 G1 F900"] + [f"X{x:.3f} Y{y:.3f}" for x, y in points]
    steps = np.diff(np.vstack([[0.0, 0.0], points]), axis=0)
    incremental = ["G91 G1 F900"] + [f"X{dx:.3f} Y{dy:.3f}" for dx, dy in np.round(steps, 3)]
    a, b = parse("\n".join(absolute)).moves, parse("\n".join(incremental)).moves
    assert len(a) == len(b) == len(points)
    for ma, mb in zip(a, b, strict=True):
        assert mb.end == pytest.approx(ma.end, abs=1e-12)
        assert mb.feed == ma.feed
    assert a[-1].end == pytest.approx(tuple(points[-1] * MM), abs=1e-15)


def test_inch_units_convert_lengths_and_feed_and_switching_keeps_the_physical_feed():
    # RS-274/NGC sets the feed before the units: F in a block with G20 is in the units in
    # force before it (LinuxCNC: "G20 F118.5" in G21 runs at 118.5 mm/min)
    moves = parse("G20 G1 X1 Y-2 F10\nG21 X50\nG20 Y1 F20\nX2 F30").moves
    assert moves[0].end == pytest.approx((INCH, -2 * INCH), abs=1e-15)
    assert moves[0].feed == pytest.approx(10 * MM / 60.0, rel=1e-15)
    assert moves[1].end == pytest.approx((50 * MM, -2 * INCH), abs=1e-15)
    assert moves[1].feed == moves[0].feed  # stored in SI: G21 changes no physical speed
    assert moves[2].end == pytest.approx((50 * MM, INCH), abs=1e-15)
    assert moves[2].feed == pytest.approx(20 * MM / 60.0, rel=1e-15)
    assert moves[3].feed == pytest.approx(30 * INCH / 60.0, rel=1e-15)


def test_start_position_is_honoured_in_both_distance_modes():
    start = (0.1, -0.2)
    a = parse("G0 X5", start=start).moves[0]
    b = parse("G91 G0 X5", start=start).moves[0]
    assert a.start == b.start == start
    assert a.end == pytest.approx((5 * MM, -0.2))
    assert b.end == pytest.approx((0.1 + 5 * MM, -0.2))


# -- arcs -----------------------------------------------------------------------------------

def reference_center_from_radius(start, end, radius, ccw):
    """Independent R-arc centre: intersect the two circles of |R| around start and end and
    keep the candidate whose sweep in the programmed direction is <= π for R > 0."""
    s, e = complex(*start), complex(*end)
    r = abs(radius)
    mid, half = (s + e) / 2, abs(e - s) / 2
    normal = (e - s) / abs(e - s) * 1j
    height = math.sqrt(max(r * r - half * half, 0.0))
    for center in (mid + height * normal, mid - height * normal):
        turn = cmath.phase((e - center) / (s - center))  # (-π, π]
        sweep = turn % (2 * math.pi) if ccw else (-turn) % (2 * math.pi)
        if (sweep <= math.pi + 1e-12) == (radius > 0):
            return center.real, center.imag
    raise AssertionError("no candidate centre")


def reference_sweep(move: Move) -> float:
    """Signed sweep from the phase of the complex quotient (end - c) / (start - c)."""
    s, e, c = complex(*move.start), complex(*move.end), complex(*move.center)
    turn = cmath.phase((e - c) / (s - c)) % (2 * math.pi) or 2 * math.pi
    sweep = turn if move.ccw else (2 * math.pi - turn) or 2 * math.pi
    if move.start == move.end:
        sweep = 2 * math.pi
    sweep += 2 * math.pi * move.turns
    return sweep if move.ccw else -sweep


R_CASES = [
    # start mm, end mm, R mm, ccw
    ((0, 0), (10, 0), 5, True),
    ((0, 0), (10, 0), 5, False),
    ((0, 0), (10, 0), 8, True),
    ((0, 0), (10, 0), 8, False),
    ((0, 0), (10, 0), -8, True),
    ((0, 0), (10, 0), -8, False),
    ((3, -4), (-2.5, 7.25), 20, True),
    ((3, -4), (-2.5, 7.25), -20, False),
    ((1, 1), (1.001, 1), 0.7, True),
]


@pytest.mark.parametrize(("start", "end", "radius", "ccw"), R_CASES)
def test_r_arc_centre_and_sweep_match_an_independent_computation(start, end, radius, ccw):
    code = "G3" if ccw else "G2"
    text = f"{code} X{end[0]} Y{end[1]} R{radius} F100"
    (arc,) = parse(text, start=(start[0] * MM, start[1] * MM)).moves
    ref = reference_center_from_radius(np.multiply(start, MM), np.multiply(end, MM),
                                       radius * MM, ccw)
    assert arc.kind == "arc" and arc.ccw == ccw and arc.turns == 0
    assert arc.center == pytest.approx(ref, abs=1e-12)
    assert arc.radius == pytest.approx(abs(radius) * MM, rel=1e-12)
    assert (abs(arc.sweep) <= math.pi + 1e-12) == (radius > 0)
    assert math.copysign(1.0, arc.sweep) == (1.0 if ccw else -1.0)
    assert arc.sweep == pytest.approx(reference_sweep(arc), abs=1e-12)


# Points on circles with exact decimal coordinates (3-4-5 triangles), centre (cx, cy), r = 5
IJ_CASES = [
    # centre mm, start offset, end offset, ccw, P
    ((0, 0), (5, 0), (3, 4), True, None),
    ((0, 0), (5, 0), (3, 4), False, None),
    ((10, -20), (-4, 3), (0, -5), True, None),
    ((10, -20), (-4, 3), (4, 3), False, None),
    ((2.5, 2.5), (0, 5), (0, 5), True, None),     # full circle
    ((2.5, 2.5), (0, 5), (0, 5), False, 3),        # full circle, three turns
    ((0, 0), (5, 0), (-3, -4), True, 2),           # an arc plus one extra turn
]


@pytest.mark.parametrize(("center", "s_off", "e_off", "ccw", "p"), IJ_CASES)
def test_ij_arcs_on_exact_circles(center, s_off, e_off, ccw, p):
    cx, cy = center
    sx, sy = cx + s_off[0], cy + s_off[1]
    ex, ey = cx + e_off[0], cy + e_off[1]
    code = "G3" if ccw else "G2"
    turns = "" if p is None else f" P{p}"
    text = (f"G0 X{sx} Y{sy}\n"
            f"{code} X{ex} Y{ey} I{cx - sx} J{cy - sy}{turns} F300")
    arc = parse(text).moves[1]
    assert arc.center == pytest.approx((cx * MM, cy * MM), abs=1e-15)
    assert arc.end == pytest.approx((ex * MM, ey * MM), abs=1e-15)
    assert arc.turns == (0 if p is None else p - 1)
    assert arc.radius == pytest.approx(5 * MM, rel=1e-13)
    assert arc.sweep == pytest.approx(reference_sweep(arc), abs=1e-12)
    assert arc.length == pytest.approx(5 * MM * abs(arc.sweep), rel=1e-13)
    assert arc.feed == pytest.approx(300 * MM_PER_MIN)


def test_full_circle_forms():
    # I/J without X/Y, and X/Y equal to the start: both full circles, in either distance mode
    for text in ("G0 X10\nG2 I-10 F100", "G0 X10\nG2 X10 Y0 I-10 F100",
                 "G0 X10\nG91 G2 X0 Y0 I-10 F100"):
        arc = parse(text).moves[1]
        assert arc.start == arc.end == approx_point(10, 0)
        assert arc.sweep == pytest.approx(-2 * math.pi, rel=1e-15)
        assert arc.length == pytest.approx(2 * math.pi * 10 * MM, rel=1e-14)


def test_full_circle_survives_a_unit_switch_that_differs_in_the_last_bit():
    # 25.4 mm and 1 inch are the same point but not the same double
    arc = parse("G21 G0 X25.4\nG20 G3 X1 I-1 F10").moves[1]
    assert arc.start == arc.end
    assert arc.sweep == pytest.approx(2 * math.pi)


def test_end_points_within_a_nanometre_are_the_start():
    arc = parse("G0 X10\nG2 X10.0000009 I-10 F100").moves[1]
    assert arc.end == arc.start and arc.sweep == -2 * math.pi
    assert parse("G1 X0.0000009 F100").moves == ()
    short = parse("G0 X10\nG3 X10 Y0.000002 I-10 F100").moves[1]  # 2 nm: a tiny arc
    assert short.sweep == pytest.approx(2e-9 / 10e-3, rel=1e-6)


def test_ij_centre_is_corrected_onto_the_bisector():
    # end 0.003 mm outside a 10 mm quarter circle: allowed 0.01 mm, so accepted and corrected
    arc = parse("G0 X10\nG3 X0 Y10.003 I-10 J0 F100").moves[1]
    s, e, c = (np.array(p) for p in (arc.start, arc.end, (0.0, 0.0)))
    # independent reference: nearest point to the programmed centre on |P-S| = |P-E|
    normal, rhs = 2 * (e - s), e @ e - s @ s
    ref = c + (rhs - normal @ c) * normal / (normal @ normal)
    assert arc.center == pytest.approx(tuple(ref), abs=1e-15)
    assert math.dist(arc.center, arc.start) == pytest.approx(math.dist(arc.center, arc.end),
                                                             abs=1e-15)
    assert math.dist(arc.center, (0.0, 0.0)) < 0.003 * MM


@pytest.mark.parametrize(("units", "radius", "allowed"), [
    ("G21", 1, 0.02 * math.sqrt(2)), ("G21", 50, 0.05), ("G21", 5000, 2 * math.sqrt(2)),
    ("G20", 1, 0.002 * math.sqrt(2)), ("G20", 5, 0.005), ("G20", 500, 0.2 * math.sqrt(2))])
def test_arc_tolerance_boundary_is_linuxcncs(units, radius, allowed):
    # end point radially off by just under / just over LinuxCNC's tolerance, half circle
    # (checked against rs274 itself in tests/controller/test_linuxcnc.py)
    for factor, ok in ((0.95, True), (1.05, False)):
        off = allowed * factor
        text = f"{units} G0 X{radius}\nG3 X{-radius - off:.9f} Y0 I{-radius} F100"
        if ok:
            assert parse(text).moves[1].kind == "arc"
        else:
            with pytest.raises(GCodeError) as info:
                parse(text)
            assert info.value.code == "arc-end-off-circle"
    unit = MM if units == "G21" else INCH
    tol = ArcTolerance.linuxcnc("mm" if units == "G21" else "inch")
    assert tol.allowed(radius * unit) == pytest.approx(allowed * unit)


def _distance_to_spiral(point, center, a0, sweep, r0, r1):
    """Distance of ``point`` from LinuxCNC's spiral (radius linear in the angle)."""
    angle = math.atan2(point[1] - center[1], point[0] - center[0])
    f = ((angle - a0) % (2 * math.pi)) / abs(sweep) if sweep > 0 else \
        ((a0 - angle) % (2 * math.pi)) / abs(sweep)
    f = min(max(f, 0.0), 1.0)
    return abs(math.dist(point, center) - (r0 + f * (r1 - r0)))


def test_short_chord_runs_linuxcncs_spiral_in_exact_pieces_within_the_stated_bound():
    # start (10, 0), end 0.01 mm away along the circle but 0.005 mm outside it
    a = -0.001
    end = f"X{10.005 * math.cos(a):.9f} Y{10.005 * math.sin(a):.9f}"
    short = parse(f"G0 X10\nG2 {end} I-10 F100").moves[1:]  # tiny clockwise arc: one piece
    assert len(short) == 1 and abs(short[0].sweep) < 0.01
    # nearly a full circle: the corrected circle would move its centre by 5 mm, so the
    # spiral is run instead, as exact arcs of at most 90°
    pieces = parse(f"G0 X10\nG3 {end} I-10 F100").moves[1:]
    assert len(pieces) == 4
    assert all(p.kind == "arc" and abs(p.sweep) <= math.pi / 2 + 1e-9 for p in pieces)
    for p, q in itertools.pairwise(pieces):
        assert p.end == q.start
    r0, r1 = 10 * MM, 10.005 * MM
    sweep = sum(p.sweep for p in pieces)
    assert sweep == pytest.approx(2 * math.pi - 0.001, abs=1e-6)
    bound = 1.71 * (r1 - r0) / len(pieces)
    worst = 0.0
    for p in pieces:
        a_start = math.atan2(p.start[1] - p.center[1], p.start[0] - p.center[0])
        for t in np.linspace(0.0, 1.0, 201):
            angle = a_start + t * p.sweep
            point = (p.center[0] + p.radius * math.cos(angle),
                     p.center[1] + p.radius * math.sin(angle))
            worst = max(worst, _distance_to_spiral(point, (0.0, 0.0), 0.0, sweep, r0, r1))
    assert worst <= bound
    assert worst > 0.0


def test_r_arc_slightly_too_short_becomes_a_half_circle():
    arc = parse("G2 X10.0015 R5 F100").moves[0]
    assert arc.center == pytest.approx((10.0015 / 2 * MM, 0.0), abs=1e-15)
    assert arc.sweep == pytest.approx(-math.pi)


def test_arc_tolerance_is_configurable():
    text = "G0 X10\nG3 X-10.0015 I-10 F100"
    parse(text)
    with pytest.raises(GCodeError, match="off the circle"):
        parse(text, arc_tolerance=ArcTolerance(absolute=1e-6, relative=0.0))


def test_path_length_against_the_analytic_sum():
    text = ("G0 X-5\nG1 X10 F500\n"          # rapid 5 mm, line 15 mm
            "G3 X0 Y10 I-10\n"              # quarter circle r 10
            "G2 X0 Y10 J-5 P2\n"            # two full turns r 5
            "G1 X0 Y0\nM2")
    prog = parse(text)
    feed = 15 + 0.5 * math.pi * 10 + 2 * 2 * math.pi * 5 + 10
    assert prog.feed_length == pytest.approx(feed * MM, rel=1e-14)
    assert prog.path_length == pytest.approx((feed + 5) * MM, rel=1e-14)


# -- events, dwell, end of program ----------------------------------------------------------

def test_events_in_execution_order_with_si_values():
    prog = parse("M8 M3 T2 M6 S1200 G4 P1.5 M30")
    speed, *rest = prog.items
    assert speed.kind == "spindle_speed"
    assert speed.value == pytest.approx(1200 * 2 * math.pi / 60, rel=1e-15)
    assert tuple(rest) == (
        Event("tool_select", 2, 1),
        Event("tool_change", 2, 1),
        Event("spindle_cw", None, 1),
        Event("coolant_flood", None, 1),
        Dwell(1.5, 1),
        ProgramEnd("M30", 1),
    )
    assert prog.end == ProgramEnd("M30", 1)


@pytest.mark.parametrize(("word", "kind"), [("M3", "spindle_cw"), ("M4", "spindle_ccw"),
                                            ("M5", "spindle_stop"), ("M7", "coolant_mist"),
                                            ("M8", "coolant_flood"), ("M9", "coolant_off")])
def test_machine_function_events(word, kind):
    assert parse(word).items == (Event(kind, None, 1),)


def test_tool_change_without_a_selected_tool_and_modal_tool():
    interp = Interpreter()
    assert interp.execute("M6") == (Event("tool_change", None, 1),)
    interp.execute("T7", line=2)
    assert interp.execute("M6", line=3) == (Event("tool_change", 7, 3),)
    assert interp.state.tool == 7


def test_nothing_after_m2_is_read():
    prog = parse("G0 X1\nM2\nG0 X2\nthis is not G-code (at all\n")
    assert [type(i) for i in prog.items] == [Move, ProgramEnd]
    assert prog.items[-1].line == 2


def test_tape_markers():
    prog = parse("\n(header)\n%\nG0 X1\n%\nanything at all ((\n")
    assert len(prog.moves) == 1 and prog.end is None
    assert parse("G0 X1\n%\nG0 X2").moves[-1].end == approx_point(1, 0)
    assert parse("%\n%\nG0 X1").items == ()


def test_block_numbers_and_line_numbers():
    prog = parse("\n\nN10 G0 X1\n(skip)\nN0020 X2\nX3\r\nX4\rX5")
    assert [(m.line, m.block_number) for m in prog.moves] == [
        (3, 10), (5, 20), (6, None), (7, None), (8, None)]


def test_modal_state_after_a_program():
    interp = Interpreter()
    for number, text in enumerate(["G20 G91 G2 X2 I1 F10", "G18", "M4 S300 M7"], start=1):
        interp.execute(text, line=number)
    state = interp.state
    assert (state.units, state.distance, state.motion, state.plane) == (
        "inch", "incremental", "arc_cw", "xz")
    assert state.feed == pytest.approx(10 * MM / 60)   # F before G20: in millimetres
    assert (state.spindle, state.coolant) == ("ccw", "mist")
    assert state.spindle_speed == pytest.approx(300 * 2 * math.pi / 60)
    assert interp.position == pytest.approx((2 * INCH, 0.0))


BAD_ITEMS = [
    (lambda: Move("spline", (0.0, 0.0), (1.0, 0.0), 1.0), "Move.kind"),
    (lambda: Move("line", (0.0, 0.0), (1.0, 0.0), 0.0), "Move.feed"),
    (lambda: Move("rapid", (0.0, 0.0), (1.0, 0.0), 1.0), "Move.feed"),
    (lambda: Move("line", (0.0, 0.0), (1.0, 0.0), 1.0, center=(0.0, 0.0)), "Move.center"),
    (lambda: Move("arc", (0.0, 0.0), (1.0, 0.0), 1.0, center=(0.0, 1.0)), "Move.center"),
    (lambda: Move("arc", (0.0, 0.0), (0.0, 0.0), 1.0, center=(0.0, 1.0), turns=-1),
     "Move.turns"),
    (lambda: Move("arc", (0.0, 0.0), (0.0, 0.0), 1.0, center=(0.0, 1.0), ccw=1), "Move.ccw"),
    (lambda: Move("line", (0.0, math.nan), (1.0, 0.0), 1.0), "Move.start"),
    (lambda: Move("line", "ab", (1.0, 0.0), 1.0), "Move.start"),
    (lambda: Move("line", (0.0, 0.0), (1.0, 0.0), 1.0, line=0), "Move.line"),
    (lambda: Dwell(-1.0), "Dwell.duration"),
    (lambda: Event("laser_on"), "Event.kind"),
    (lambda: ProgramEnd("M0"), "ProgramEnd.code"),
    (lambda: Interpreter(start=(0.0,)), "start"),
    (lambda: Interpreter(start=(0.0, math.inf)), "start"),
    (lambda: ArcTolerance(absolute=1e-3, maximum=1e-4), "arc_tolerance.maximum"),
    (lambda: ArcTolerance(relative=-1.0), "arc_tolerance.relative"),
]


@pytest.mark.parametrize(("build", "field"), BAD_ITEMS)
def test_items_and_options_validate_their_fields(build, field):
    with pytest.raises(ConfigError) as info:
        build()
    assert info.value.field == field


@pytest.mark.parametrize("module", [gcode_pkg, interpreter_module, arcs_module])
def test_docstring_examples(module):
    result = doctest.testmod(module)
    assert result.failed == 0


@pytest.mark.parametrize("blanks", [1, 4096, 1 << 20])
def test_words_across_long_blank_runs_and_comments_keep_their_columns(blanks):
    # the lexer finds words by their letters: linear in the line (bench/lexer.py times it)
    gap = " " * blanks
    line = f"G1 X1{gap}(note{gap}){gap}Y-2.5{gap};{gap}"
    y_at = len(f"G1 X1{gap}(note{gap}){gap}") + 1
    assert lex(line) == [("G", 1.0, 1), ("X", 1.0, 4), ("Y", -2.5, y_at)]
    with pytest.raises(GCodeError) as caught:
        lex(f"G1 X1{gap}?")
    assert caught.value.column == 6 + blanks and caught.value.code == "syntax"
