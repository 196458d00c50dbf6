"""The LinuxCNC language: expressions against an independent evaluator, parameters and their
scopes, O-word control flow step by step, subroutine files, the bounds on runaway programs,
the order of execution inside a block (one test per row of ``gcode.ORDER``), and the
reader's memory on long programs."""

from __future__ import annotations

import io
import itertools
import math
import operator
import time

import numpy as np
import pytest

from twin.controller.gcode import (
    ORDER,
    Dwell,
    Event,
    Limits,
    Move,
    PathControl,
    ProgramEnd,
    ReaderOptions,
    iter_items,
    parse,
)
from twin.controller.gcode.expr import read_statement
from twin.controller.gcode.lexer import clean
from twin.controller.gcode.tape import Tape
from twin.errors import ConfigError, GCodeError
from twin.units import INCH, MM


def value_of(expression: str, parameters: dict | None = None) -> float:
    """The value LinuxCNC's language gives ``expression`` (as an X word)."""
    table = parameters or {}

    def lookup(key, column):
        return table.get(key, 0.0)

    statement = read_statement(clean(f"X{expression}"), 1, f"X{expression}", lookup,
                               lambda name: name in table)
    return statement.words[0][1]


# ------------------------------------------------------------------------ expressions
_BINARY = {"+": operator.add, "-": operator.sub, "*": operator.mul, "/": operator.truediv,
           "**": math.pow, "MOD": lambda a, b: math.fmod(a, b) + (abs(b) if math.fmod(a, b) < 0
                                                                  else 0.0),
           "EQ": lambda a, b: float(abs(a - b) < 1e-4),
           "NE": lambda a, b: float(abs(a - b) >= 1e-4),
           "GT": lambda a, b: float(a > b), "GE": lambda a, b: float(a >= b),
           "LT": lambda a, b: float(a < b), "LE": lambda a, b: float(a <= b),
           "AND": lambda a, b: float(bool(a) and bool(b)),
           "OR": lambda a, b: float(bool(a) or bool(b)),
           "XOR": lambda a, b: float(bool(a) != bool(b))}
_UNARY = {"ABS": abs, "SIN": lambda x: math.sin(math.radians(x)),
          "COS": lambda x: math.cos(math.radians(x)), "FIX": math.floor, "FUP": math.ceil,
          "SQRT": lambda x: math.sqrt(abs(x)), "EXP": lambda x: math.exp(min(x, 20.0)),
          "ROUND": lambda x: math.floor(x + 0.5) if x >= 0 else math.ceil(x - 0.5)}


def _tree(rng: np.random.Generator, depth: int) -> tuple[str, float]:
    """A random fully bracketed expression and its value, computed in Python."""
    if depth == 0 or rng.random() < 0.25:
        value = float(np.round(rng.uniform(-50, 50), int(rng.integers(0, 4))))
        return f"{value:g}" if value >= 0 else f"[0 - {-value:g}]", value
    if rng.random() < 0.3:
        name = str(rng.choice(list(_UNARY)))
        text, value = _tree(rng, depth - 1)
        if name == "SQRT":
            return f"SQRT[ABS[{text}]]", math.sqrt(abs(value))
        if name == "EXP":
            return f"EXP[[{text}] MOD 20]", math.exp(_BINARY["MOD"](value, 20.0))
        return f"{name}[{text}]", float(_UNARY[name](value))
    op = str(rng.choice(list(_BINARY)))
    left, a = _tree(rng, depth - 1)
    right, b = _tree(rng, depth - 1)
    if op in ("/", "MOD") and abs(b) < 1e-3:
        op = "+"
    if op == "**":
        a, b = abs(a) % 3, float(int(abs(b)) % 4)
        left, right = f"[ABS[{left}] MOD 3]", f"[FIX[ABS[{right}]] MOD 4]"
    return f"[{left} {op} {right}]", float(_BINARY[op](a, b))


@pytest.mark.parametrize("seed", range(300))
def test_random_expressions_match_an_independent_evaluator(seed):
    rng = np.random.default_rng(seed)
    text, expected = _tree(rng, 4)
    if not math.isfinite(expected) or abs(expected) >= 1e9:
        pytest.skip("out of the reader's range by construction")   # rare: a power tower
    assert value_of(text) == pytest.approx(expected, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize(("text", "value"), [
    ("[2 + 3 * 4]", 14), ("[2 * 3 + 4]", 10), ("[10 - 4 - 3]", 3), ("[64 / 4 / 2]", 8),
    ("[2 ** 3 ** 2]", 64),                  # left-associative, as LinuxCNC
    ("[2 * 3 ** 2]", 18), ("[1 + 2 EQ 3]", 1), ("[1 EQ 1 AND 0]", 0),
    ("[1 OR 0 AND 0]", 0),                  # AND, OR, XOR share one level, left to right
    ("[-7 MOD 3]", 2), ("[7 MOD -3]", 1), ("[1 LT 2 EQ 1]", 1),
    ("-[1 + 2]", -3), ("+#1", 5), ("-#1", -5), ("#[2 + 3]", 7), ("##2", 7),
    ("ATAN[1]/[1]", 45), ("ATAN[1]/[-1]", 135), ("ACOS[0]", 90), ("ASIN[1]", 90),
    ("ROUND[2.5]", 3), ("ROUND[-2.5]", -3), ("FIX[-2.5]", -3), ("FUP[-2.5]", -2),
    ("LN[EXP[2]]", 2), ("[1.00005 EQ 1]", 1), ("[1.0002 EQ 1]", 0), ("[1.0002 NE 1]", 1),
    ("EXISTS[#<named>]", 1), ("EXISTS[#<other>]", 0), ("#<named>", 3),
])
def test_precedence_functions_and_parameters_as_linuxcnc(text, value):
    assert value_of(text, {1: 5.0, 2: 5.0, 5: 7.0, "named": 3.0}) == pytest.approx(value)


# ------------------------------------------------------------------------ parameters
def ends(text: str, **options) -> list[tuple[float, float]]:
    """The end points of the moves of a program (mm)."""
    items = parse(text, options=ReaderOptions(**options) if options else None)
    return [(round(m.end[0] / MM, 9), round(m.end[1] / MM, 9)) for m in items
            if isinstance(m, Move)]


def test_assignments_take_effect_after_the_line_is_read():
    assert ends("G1 F100\n#1 = 2\n#1 = 5 X#1 Y[#1 * 2]\nX#1") == [(2, 4), (5, 4)]


def test_scopes_locals_globals_arguments_and_the_returned_value():
    text = """G1 F100
#<local> = 1
#<_global> = 2
#31 = 3
o<f> sub
  (#1, #2 are the arguments; #<local> here is the sub's own)
  #<local> = [#1 * 10]
  #<_global> = [#<_global> + 1]
  #31 = [#31 + 1]
  G1 X#<local> Y#2
  o<f> return [#1 + #2]
o<f> endsub
o<f> call [4] [5]
G1 X#<local> Y#<_value>
G1 X#<_global> Y#31
o<f> call [1] [1]
G1 X#<_value_returned> Y#<_value>
M2"""
    assert ends(text) == [(40, 5), (1, 9), (3, 4), (10, 1), (1, 2)]
    with pytest.raises(GCodeError, match="#<local> is not set") as info:
        parse("G1 F1\n#<local> = 1\no<g> sub\nG1 X#<local>\no<g> endsub\no<g> call")
    assert (info.value.line, info.value.column) == (4, 5)


# ------------------------------------------------------------------------ control flow
def test_every_kind_of_loop_and_branch_step_by_step():
    text = """G1 F100
#1 = 0
o1 while [#1 LT 3]
  #1 = [#1 + 1]
  o2 if [#1 EQ 2]
    o1 continue
  o2 endif
  G1 X#1 Y1
o1 endwhile
#2 = 0
o3 do
  #2 = [#2 + 1]
  o4 if [#2 GT 2]
    o3 break
  o4 elseif [#2 EQ 1]
    G1 X10 Y#2
  o4 else
    G1 X20 Y#2
  o4 endif
o3 while [1]
o5 repeat [2]
  o6 repeat [2]
    G91
    G1 X1
    G90
  o6 endrepeat
  G1 Y7
o5 endrepeat
o7 repeat [0]
  G1 X99
o7 endrepeat
o8 while [0]
  G1 X98
o8 endwhile
M2"""
    assert ends(text) == [(1, 1), (3, 1), (10, 1), (20, 2), (21, 2), (22, 2), (22, 7),
                          (23, 7), (24, 7)]


def test_recursion_that_ends_and_recursion_that_does_not():
    text = """G1 F100
o<fact> sub
  o1 if [#1 LE 1]
    o<fact> return [1]
  o1 endif
  o<fact> call [#1 - 1]
  o<fact> return [#1 * #<_value>]
o<fact> endsub
o<fact> call [6]
G1 X#<_value>
M2"""
    assert ends(text) == [(720, 0)]
    runaway = "o<r> sub\no<r> call\no<r> endsub\no<r> call\nM2"
    t0 = time.perf_counter()
    with pytest.raises(GCodeError) as info:
        parse(runaway, options=ReaderOptions(limits=Limits(call_depth=20)))
    assert info.value.code == "call-depth" and "deeper than 20" in info.value.message
    assert time.perf_counter() - t0 < 5.0


@pytest.mark.parametrize("loop", ["o1 while [1]\n#1=[#1+1]\no1 endwhile",
                                  "o1 do\nG0 X1\nG0 X0\no1 while [1]",
                                  "o1 repeat [100000000]\nG0 X1\no1 endrepeat"])
def test_a_runaway_loop_ends_in_an_error_at_its_line(loop):
    t0 = time.perf_counter()
    with pytest.raises(GCodeError) as info:
        for _ in iter_items(io.StringIO(f"G0 X0\n{loop}\nM2"),
                            options=ReaderOptions(limits=Limits(loop_iterations=1000))):
            pass
    assert info.value.code == "loop-limit" and info.value.line == 2
    assert "1000" in info.value.message and "loop_iterations" in info.value.message
    assert time.perf_counter() - t0 < 5.0


def test_a_subroutine_file_is_found_and_its_errors_name_it(tmp_path):
    (tmp_path / "corner.ngc").write_text(
        "(a library file)\no<corner> sub\n  G1 X#1 Y#2\no<corner> endsub\nM2\n")
    (tmp_path / "broken.ngc").write_text("o<broken> sub\n  G1 X[1 / 0]\no<broken> endsub\n")
    program = tmp_path / "part.ngc"
    program.write_text("G21 G1 F300\no<corner> call [3] [4]\no<corner> call [5] [6]\nM2\n")
    from twin.controller.gcode import read_file
    moves = [m for m in read_file(program) if isinstance(m, Move)]
    assert [v / MM for m in moves for v in m.end] == pytest.approx([3, 4, 5, 6])
    program.write_text("G21 G1 F300\no<broken> call\nM2\n")
    with pytest.raises(GCodeError) as info:
        list(read_file(program))
    error = info.value
    assert error.file == str(tmp_path / "broken.ngc")
    assert (error.line, error.column, error.code) == (2, 10, "bad-value")
    assert str(error).startswith(f"{tmp_path / 'broken.ngc'}, line 2, col 10: division")


def test_the_tape_keeps_only_what_a_loop_may_go_back_to():
    tape = Tape(f"G0 X{i}\n" for i in range(100_000))
    while tape.next() is not None:
        assert not tape._buffer
    tape = Tape(["a", "b", "c", "d", "e"])
    tape.next()
    tape.mark(0)                 # the line read last
    assert [tape.next() for _ in range(3)] == ["b", "c", "d"]
    tape.seek(0)
    assert tape.next() == "a"
    tape.release(0)
    assert len(tape._buffer) == 3        # b, c, d: still ahead of the position
    assert [tape.next() for _ in range(4)] == ["b", "c", "d", "e"]
    assert tape.next() is None and not tape._buffer


# ------------------------------------------------------------------------ order of execution
def items_of(text: str, **options) -> list:
    return list(parse(text, options=ReaderOptions(**options) if options else None))


ORDER_CASES = {
    "parameters": lambda: ends("G1 F1\n#1=2\n#1=3 X#1\nY#1") == [(2, 0), (2, 3)],
    "O-words": lambda: _raises("G0 X1 o1 if [1]", "must begin its line"),
    "F": lambda: items_of("G20 G1 X1 F10")[0].feed == pytest.approx(10 * MM / 60),
    "S": lambda: [i.kind for i in items_of("M3 S100", z="tool")] ==
    ["spindle_speed", "spindle_cw", "tool_on"],
    "T": lambda: [(i.kind, i.value) for i in items_of("T3 M6")] ==
    [("tool_select", 3), ("tool_change", 3)],
    "M6": lambda: [i.kind for i in items_of("M3 M6 T2")] ==
    ["tool_select", "tool_change", "spindle_cw"],
    "M3, M4, M5": lambda: [i.kind for i in items_of("M8 M3")] == ["spindle_cw",
                                                                   "coolant_flood"],
    "M7, M8, M9": lambda: [type(i).__name__ for i in items_of("G4 P1 M9")] ==
    ["Event", "Dwell"],
    "G4": lambda: [type(i).__name__ for i in items_of("G1 F10\nG4 P1 X1")] ==
    ["Dwell", "Move"],
    "G17, G18, G19": lambda: _raises("G1 F1\nG18 X1", "only the XY plane"),
    "G20, G21": lambda: items_of("G1 F1\nG20 X1")[0].end[0] == pytest.approx(INCH),
    "G40, G43, G49": lambda: len(items_of("G1 F1 G40 G43 H1 X1")) == 1,
    "G54–G59.3": lambda: ends("G10 L2 P2 X5\nG1 F1\nG55 X1") == [(6, 0)],
    "G61, G61.1, G64": lambda: [type(i).__name__ for i in items_of("G1 F1 G64 P0.1 X1")] ==
    ["PathControl", "Move"],
    "G90, G91": lambda: ends("G1 F1 X1\nG91 X1") == [(1, 0), (2, 0)],
    "G90.1, G91.1": lambda: items_of("G1 F1 X2\nG90.1 G2 X0 I1 J0")[1].center ==
    pytest.approx((MM, 0.0)),
    "G10, G28, G30, G92": lambda: ends("G1 F1 X1\nG92 X0\nX1") == [(1, 0), (2, 0)],
    "G0–G3, G53": lambda: ends("G10 L2 P1 X5\nG1 F1 X1\nG53 G1 X1") == [(6, 0), (1, 0)],
    "M0, M1, M60": lambda: [type(i).__name__ for i in items_of("G1 F1 X1 M0")] ==
    ["Move", "Event"],
    "M2, M30": lambda: [type(i).__name__ for i in items_of("G1 F1 X1 M2\nG1 X5")] ==
    ["Move", "ProgramEnd"],
}


def _raises(text: str, words: str) -> bool:
    try:
        parse(text)
    except GCodeError as error:
        return words in error.message
    return False


@pytest.mark.parametrize(("row", "note"), ORDER, ids=[row for row, _ in ORDER])
def test_each_row_of_the_order_of_execution(row, note):
    assert ORDER_CASES[row](), note


def test_the_order_table_is_tested_row_by_row():
    assert [row for row, _ in ORDER] == list(ORDER_CASES)


def test_item_types_of_the_reader():
    assert {type(i) for i in items_of("G1 F1 G64 P0 X1\nG4 P1\nM3\nM2")} == {
        Move, PathControl, Dwell, Event, ProgramEnd}


# ------------------------------------------------------------------------ G64 Q
def _chorded_circle(chord_mm: float, radius_mm: float = 20.0) -> tuple[str, list]:
    n = int(2 * math.pi * radius_mm / chord_mm)
    points = [(radius_mm * math.cos(2 * math.pi * k / n),
               radius_mm * math.sin(2 * math.pi * k / n)) for k in range(n + 1)]
    lines = [f"G1 X{x:.4f} Y{y:.4f}" for x, y in points]
    return "\n".join(lines), [(float(f"{x:.4f}"), float(f"{y:.4f}")) for x, y in points]


@pytest.mark.parametrize("q", [0.001, 0.01, 0.05])
def test_g64_q_merges_collinear_chords_within_q(q):
    body, points = _chorded_circle(0.05)
    header = f"G21 G90 F600\nG0 X20 Y0\nG64 P0.1 Q{q}\n"
    merged = [m for m in parse(header + body) if isinstance(m, Move) and m.kind == "line"]
    plain = [m for m in parse(header.replace(f" Q{q}", "") + body)
             if isinstance(m, Move) and m.kind == "line"]
    assert len(plain) == len(points) - 1
    assert len(merged) < len(plain)
    for a, b in itertools.pairwise(merged):         # one continuous path
        assert a.end == b.start
    # every programmed point lies within Q of the merged path
    a = np.array([m.start for m in merged])
    b = np.array([m.end for m in merged])
    ab = b - a
    for p in np.array(points) * MM:
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        best = np.min(np.linalg.norm(p - (a + t[:, None] * ab), axis=1))
        assert best <= q * MM * (1 + 1e-9)
    # fewer lines the larger Q
    if q == 0.05:
        assert len(merged) < len(plain) / 3


def test_g64_q_keeps_corners_feeds_and_reversals():
    text = ("G21 G90 F600 G64 P0.1 Q0.01\nG1 X10\nX20\nX30\nY10\nY20\nX40 F300\nX30\nX20\n"
            "G64\nX10\nX0\nM2")
    lines = [(round(m.start[0] / MM, 9), round(m.start[1] / MM, 9), round(m.end[0] / MM, 9),
              round(m.end[1] / MM, 9), m.line) for m in parse(text) if isinstance(m, Move)]
    assert lines == [
        (0, 0, 30, 0, 2),             # three collinear lines: one
        (30, 0, 30, 20, 5),           # the corner stays
        (30, 20, 40, 20, 7),          # another feed
        (40, 20, 20, 20, 8),          # turning back ends the chain; then a new one
        (20, 20, 10, 20, 11),         # after G64 without Q: no merging
        (10, 20, 0, 20, 12)]


def test_work_offsets_from_the_machine_file_and_from_the_program():
    from twin.config import load_machine
    from twin.session.setup import reader_options

    cfg = load_machine("laser_belt").with_overrides(
        {"controller.gcode.work_offsets": {"G55": [0.01, 0.02], "G59.3": [-0.005, 0.0]}})
    options = reader_options(cfg)
    text = ("G21 G90 G1 F100 G55 X1 Y1\nG59.3 X1\nG54 X1\nG10 L2 P2 X0 Y0\nG55 X1 Y1\n"
            "G1 X[#5241 * 1000] Y#5242\nM2")
    ends_mm = [(round(m.end[0] / MM, 9), round(m.end[1] / MM, 9))
               for m in parse(text, options=options) if isinstance(m, Move)]
    assert ends_mm == [(11, 21), (-4, 21), (1, 21), (1, 1), (0, 0)]
    with pytest.raises(ConfigError, match=r"work_offsets\.G53"):
        load_machine("laser_belt").with_overrides(
            {"controller.gcode.work_offsets": {"G53": [0.0, 0.0]}})


def test_the_docs_table_is_the_order_of_execution():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "GCODE.md").read_text()
    rows = [line.split(" | ") for line in doc.splitlines()
            if line.startswith("| ") and line.split(" | ")[0][2:].isdigit()]
    assert [(words, note.rstrip(" |")) for _, words, note in rows] == list(ORDER)


def test_canned_cycles_run_their_holes_and_plunge_the_tool():
    text = ("G21 G90 F100\nG0 Z5\nG82 X10 Y10 R2 Z-1 P0.5\nX20\nG91 G81 X5 R2 Z-1 L3\nG90 G80\n"
            "G0 X0 Y0\nM2")
    kinds = [(type(i).__name__, getattr(i, "kind", None)) for i in
             parse(text, options=ReaderOptions(z="tool")) if not isinstance(i, ProgramEnd)]
    hole = [("Move", "rapid"), ("Event", "tool_on"), ("Dwell", None), ("Event", "tool_off")]
    drill = [("Move", "rapid"), ("Event", "tool_on"), ("Event", "tool_off")]
    assert kinds == [*hole, *hole, *drill, *drill, *drill, ("Move", "rapid")]
    holes = [m.end for m in parse(text, options=ReaderOptions(z="ignore"))
             if isinstance(m, Move)][:-1]
    assert [(round(x / MM, 9), round(y / MM, 9)) for x, y in holes] == [
        (10, 10), (20, 10), (25, 10), (30, 10), (35, 10)]
    with pytest.raises(GCodeError, match="canned cycles"):
        parse("G21 G90 F100\nG82 X10 Y10 R2 P0.5")   # z = "error": they drill along Z


# ------------------------------------------------------------------------ G5, G5.1
def _within_chords(curve: np.ndarray, moves: list) -> float:
    """Largest distance of the curve's points from the chord polyline (m)."""
    a = np.array([m.start for m in moves])
    b = np.array([m.end for m in moves])
    ab = b - a
    worst = 0.0
    for p in curve:
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        worst = max(worst, float(np.min(np.linalg.norm(p - (a + t[:, None] * ab), axis=1))))
    return worst


def test_g5_and_g5_1_run_as_chords_within_the_tolerance_of_the_curve():
    from twin.controller.gcode.splines import SPLINE_TOLERANCE

    text = "G21 G90 G1 F600 X0 Y0\nG5 I0 J30 P0 Q-30 X10 Y10\nG5 P0 Q-30 X20 Y20\n" \
           "G5.1 X40 Y0 I10 J-25\nM2"
    moves = [m for m in parse(text) if isinstance(m, Move)]
    t = np.linspace(0.0, 1.0, 2001)[:, None]

    def bezier(p0, p1, p2, p3):
        p0, p1, p2, p3 = (np.array(p) * MM for p in (p0, p1, p2, p3))
        return ((1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * p1 + 3 * (1 - t) * t ** 2 * p2
                + t ** 3 * p3)

    first = bezier((0, 0), (0, 30), (10, -20), (10, 10))
    second = bezier((10, 10), (10, 40), (20, -10), (20, 20))   # I, J mirror the last P, Q
    third = (1 - t) ** 2 * np.array([20, 20]) * MM + 2 * (1 - t) * t * np.array([30, -5]) \
        * MM + t ** 2 * np.array([40, 0]) * MM                 # the quadratic itself
    for curve, line in ((first, 2), (second, 3), (third, 4)):
        chords = [m for m in moves if m.line == line]
        assert len(chords) > 10
        assert chords[-1].end == pytest.approx(tuple(curve[-1]), abs=1e-15)
        assert _within_chords(curve, chords) <= SPLINE_TOLERANCE * (1 + 1e-9)
        assert all(m.kind == "line" and m.feed == pytest.approx(0.01) for m in chords)
    with pytest.raises(GCodeError, match="needs I and J unless it follows a G5"):
        parse("G21 G1 F1 X1\nG5 P0 Q1 X2 Y2")
    with pytest.raises(GCodeError, match=r"G5\.1 needs I and J"):
        parse("G21 G1 F1\nG5.1 X2 Y2 I1")
