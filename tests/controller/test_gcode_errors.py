"""Every G-code error kind with its line, column and code; a bad block changes nothing."""

from __future__ import annotations

import re

import pytest

import twin.controller.gcode as gcode_pkg
from twin.controller.gcode import Interpreter, parse
from twin.errors import GCodeError

# (program, line, column, code, words the message must contain)
ERRORS = [
    # syntax and numbers
    ("G0 X1.2.3", 1, 8, "syntax", "number without a letter"),
    ("G0 X1 #", 1, 7, "syntax", "'#' without a parameter"),
    ("G0 X1 %", 1, 7, "syntax", "'%'"),
    ("G0 X1 é", 1, 7, "syntax", "'é'"),
    ("G0 X1 )", 1, 7, "syntax", "')' without"),
    ("G0 X", 1, 4, "bad-number", "X word without a valid number"),
    ("G0 X-Y1", 1, 4, "bad-number", "X word"),
    ("G0 X1000000000", 1, 4, "bad-number", "out of range"),
    # comments
    ("G0 X1 (to the end", 1, 7, "unterminated-comment", "not closed"),
    ("G0 (a (b) X1", 1, 7, "nested-comment", "do not nest"),
    # unknown and unsupported words
    ("G0 X1 Q5", 1, 7, "unused-word", "Q word without G64"),
    ("G0 X1 E5", 1, 7, "unknown-word", "unknown word E"),
    ("G1 X10.Y.25F1.5e3", 1, 16, "unknown-word", "unknown word E"),
    ("G7 X1", 1, 1, "unsupported", "lathe diameter mode"),
    ("G6 X1", 1, 1, "unknown-gcode", "unknown G code G6"),
    ("G91.2", 1, 1, "unknown-gcode", "G91.2"),
    ("M99", 1, 1, "unknown-mcode", "unknown M code M99"),
    ("M3.5", 1, 1, "unknown-mcode", "M3.5"),
    ("G95 G1 X1 F1", 1, 1, "unsupported", "G95"),
    ("G93", 1, 1, "unsupported", "G93"),
    # axes and planes this machine lacks
    ("G0 X1 Z5", 1, 7, "no-axis", "no Z axis on this machine"),
    ("G0 A5", 1, 4, "no-axis", "no A axis"),
    ("G2 X1 K1 F100", 1, 7, "no-axis", "no Z axis"),
    ("G18\nG1 X1 F100", 2, 1, "plane", "only the XY plane"),
    ("G19 G2 X1 I1 F100", 1, 5, "plane", "G19"),
    # modal groups and repeated words
    ("G0 G1 X1", 1, 4, "modal-conflict", "two motion words in one block (G0, G1)"),
    ("G90 G91", 1, 5, "modal-conflict", "two distance mode words in one block (G90, G91)"),
    ("G20 G21", 1, 5, "modal-conflict", "two units words"),
    ("M3 M5", 1, 4, "modal-conflict", "two spindle words in one block (M3, M5)"),
    ("M2 M30", 1, 4, "modal-conflict", "program end"),
    ("G1 X1 X2 F100", 1, 7, "repeated-word", "repeated X word"),
    ("G1 X1 F10 F20", 1, 11, "repeated-word", "repeated F word"),
    # words nothing uses, or two things claim
    ("G0 X1 I5", 1, 7, "unused-word", "I word without an arc"),
    ("G1 X1 R5 F100", 1, 7, "unused-word", "R word"),
    ("P1", 1, 1, "unused-word", "P word without G4"),
    ("G4 P1 G2 I0.5 F100", 1, 4, "ambiguous-word", "both G4"),
    ("G1 F100\nG4 X1.5", 2, 1, "missing-word", "G4 needs a P word"),
    ("G1 F100 X1 @1", 1, 9, "ambiguous-word", "with polar words"),
    ("G4", 1, 1, "missing-word", "G4 needs a P word"),
    # bad values
    ("G4 P-1", 1, 4, "bad-value", "dwell time"),
    ("N1.5 G0 X1", 1, 1, "bad-value", "block number"),
    ("N-3", 1, 1, "bad-value", "block number"),
    ("T1.5", 1, 1, "bad-value", "tool number"),
    ("S-100 M3", 1, 1, "bad-value", "spindle speed"),
    ("G1 X1 F-5", 1, 7, "bad-value", "feed F must be >= 0"),
    ("G2 I5 P0 F100", 1, 7, "bad-value", "number of turns"),
    ("G2 I5 P1.5 F100", 1, 7, "bad-value", "number of turns"),
    ("G0 X2000000", 1, 4, "out-of-range", "beyond"),
    # motion and feed
    ("X1", 1, 1, "no-motion-mode", "without a motion mode"),
    ("G0 X1\nG80\nY1", 3, 1, "no-motion-mode", "G0, G1, G2 or G3"),
    ("G1 X1", 1, 1, "missing-feed", "G1 needs a feed"),
    ("G2 X2 I1", 1, 1, "missing-feed", "G2 needs a feed"),
    ("G1 X1 F0", 1, 7, "zero-feed", "zero feed"),
    ("G1 F0\nX1", 2, 1, "zero-feed", "zero feed"),
    ("G1 F0\nG1 X1", 2, 1, "zero-feed", "zero feed"),
    # the LinuxCNC language
    ("G1 X#<depth> F1", 1, 5, "unset-parameter", "#<depth> is not set"),
    ("G1 X[1 + ] F1", 1, 10, "bad-number", "expected a number"),
    ("G1 X[1/0] F1", 1, 7, "bad-value", "division by zero"),
    ("G1 X[SQRT[-1]] F1", 1, 6, "bad-value", "SQRT of a negative"),
    ("G1 X[1 + 2 F1", 1, 12, "syntax", "expected an operator or ']'"),
    ("G1 X[1 + 2", 1, 5, "syntax", "not closed"),
    ("#5600.5 = 1", 1, 1, "bad-value", "not a whole number"),
    ("#6000 = 1", 1, 1, "out-of-range", "5601"),
    ("o100 while [1]\nG0 X1", 1, 1, "unclosed-block", "without its O100 endwhile"),
    ("o100 endwhile", 1, 1, "unmatched-block", "without an open O100 while"),
    ("o100 if [0]\nG0 X1", 1, 1, "unclosed-block", "no matching"),
    ("o<a> sub\no<a> sub", 2, 1, "bad-block", "inside the body"),
    ("o<nowhere> call", 1, 1, "unknown-sub", "no nowhere.ngc"),
    ("o100 while [1]\no100 endwhile", 1, 1, "loop-limit", "ran more than 100000 times"),
    ("o<r> sub\no<r> call\no<r> endsub\no<r> call", 2, 1, "call-depth", "deeper than 64"),
    ("G1 X" + "[" * 101 + "1" + "]" * 101, 1, 105, "nesting", "deeper than 100 levels"),
    ("o100 frobnicate", 1, 1, "unknown-word", "O-word without a keyword"),
    ("o100 if", 1, 1, "missing-word", "takes 1 bracketed argument"),
    ("G0 X1 o100 call", 1, 7, "syntax", "must begin its line"),
    ("G10 L2 P1 X1\nG10 L1 P1 X1", 2, 5, "unsupported", "G10 L1"),
    ("G81 X1", 1, 1, "unsupported", "canned cycles"),
    ("G38.2 X1 F1", 1, 1, "unsupported", "probing"),
    ("G41 D1", 1, 1, "unsupported", "cutter radius compensation"),
    ("M70", 1, 1, "unsupported", "modal-state save"),
    # arcs
    ("G2 X10 F100", 1, 1, "arc-missing-center", "I/J or the radius as R"),
    ("G2 X10 I5 R5 F100", 1, 11, "arc-center-and-radius", "both I/J and R"),
    ("G2 X10 I0 J0 F100", 1, 1, "arc-zero-radius", "I and J are zero"),
    ("G2 X10 R0 F100", 1, 1, "arc-zero-radius", "R is zero"),
    ("G2 X10 R4 F100", 1, 1, "arc-radius-too-small", "too small"),
    ("G3 R5 F100", 1, 1, "arc-full-circle-r", "full circle"),
    ("G0 X1\nG1 F100\nN3 G3 X1 Y0 R-5", 3, 4, "arc-full-circle-r", "I/J"),
    ("G2 X10 I4 F100", 1, 1, "arc-end-off-circle", "off the circle"),
    ("G0 X10\nG3 X0 Y10.05 I-10 F100", 2, 1, "arc-end-off-circle", "allowed 0.02828 mm"),
]


@pytest.mark.parametrize(("text", "line", "column", "code", "words"), ERRORS,
                         ids=[e[3] + ":" + e[0] for e in ERRORS])
def test_error_place_code_and_message(text, line, column, code, words):
    with pytest.raises(GCodeError) as info:
        parse(text)
    error = info.value
    assert (error.line, error.column, error.code) == (line, column, code)
    assert words in error.message
    source = text.splitlines()[line - 1]
    assert error.source == source
    first = str(error).splitlines()[0]
    assert first == f"line {line}, col {column}: {error.message}"
    # the caret line points at the column
    assert str(error).splitlines()[-1] == "    " + " " * (column - 1) + "^"


@pytest.mark.timeout(30)
@pytest.mark.parametrize(("line", "column"), [
    (" ".join(["X1    "] * 2000) + "#", 14_000),       # many blank runs, then a bad tail
    ("X" + "1 " * 5000 + "#", 1),                       # one long number: it overflows
    ("X" + " 1" * 3000 + " . .", 6005),                 # a long number, then a lone point
])
def test_pathological_lines_fail_fast_at_the_right_column(line, column):
    # a backtracking lexer takes exponential time on these; the guard is the timeout
    with pytest.raises(GCodeError) as info:
        parse(line)
    assert info.value.column == column


def test_every_documented_code_is_exercised():
    documented = set(re.findall(r"``([a-z-]+)``", gcode_pkg.__doc__.split("Error codes")[1]))
    assert documented == {e[3] for e in ERRORS}


def test_the_example_of_the_issue_word_for_word():
    text = "G21\n" * 11 + "G00 G1 X5\n"
    with pytest.raises(GCodeError) as info:
        parse(text)
    assert str(info.value).splitlines()[0] == (
        "line 12, col 5: two motion words in one block (G0, G1)")


def test_errors_after_the_end_are_not_raised_but_before_it_are():
    assert parse("M2\nG0 Z1").end is not None
    with pytest.raises(GCodeError) as info:
        parse("G0 Z1\nM2")
    assert info.value.line == 1


# -- all or nothing -------------------------------------------------------------------------

BAD_BLOCKS = [
    "G91 G0 X1 Q1",            # distance mode change in a block with an unknown word
    "G91 G1 X1 F-1",           # ... with a bad feed
    "G20 G0 X1 Z1",            # unit change in a block with a Z word
    "G91 G3 X1 Y1 I5 F50",     # incremental arc whose end is off its circle
    "G91 G18 G2 X1 I1 F50",    # plane and distance change with a motion in G18
    "G2 F50 M3 S500 T2 X1",    # arc without centre, after new feed, spindle and tool words
    "G91 G4 P-1",              # bad dwell
    "G91 M3 M4",               # modal conflict after a valid change
    "G91 G80 X1",              # motion cancelled, then axis words
]


@pytest.mark.parametrize("bad", BAD_BLOCKS)
def test_a_bad_block_changes_nothing(bad):
    interp = Interpreter()
    interp.execute("G90 G21 G17 G1 X2 Y3 F600 M5", line=1)
    state, position, blocks = interp.state, interp.position, interp.blocks
    with pytest.raises(GCodeError):
        interp.execute(bad, line=2)
    assert interp.state is state
    assert interp.position == position
    assert interp.blocks == blocks
    # the next good block runs in the old modes: absolute mm, G1 at 600 mm/min
    (move,) = interp.execute("X5", line=3)
    assert move.kind == "line"
    assert move.start == pytest.approx((2e-3, 3e-3))
    assert move.end == pytest.approx((5e-3, 3e-3))
    assert move.feed == pytest.approx(600e-3 / 60)
