"""Hostile lines are refused at their place, never by the interpreter running out of stack
or of integer digits (issue 33): nesting of brackets, functions and ``#`` references up to
100 000 deep, and numbers of any length (O-word labels, N numbers, words, expressions)."""

from __future__ import annotations

import math
import os
import random

import pytest

from twin.controller.gcode import parse
from twin.controller.gcode.expr import MAX_NESTING
from twin.errors import GCodeError

CI = bool(os.environ.get("CI"))
PREFIX = "G21 G90 G1 F100 X"          # the value under test is X's, from column 19
AT = len(PREFIX) + 1


def _nest(kind: str, depth: int) -> tuple[str, float]:
    """``X``'s value nested ``depth`` deep in one way (with ``#1 = 1``), and its value
    (mm)."""
    if kind == "brackets":
        return "[" * depth + "2" + "]" * depth, 2.0
    if kind == "abs":
        return "ABS[" * depth + "-2" + "]" * depth, 2.0
    if kind == "hashes":                            # every #1 names #1 again
        return "#" * depth + "1", 1.0
    return "#[" * depth + "1" + "]" * depth, 1.0    # indexed: #[#[#[1]]]


def _openers(line: str) -> list[int]:
    """0-based places of every '[' and '#' of X's value: each opens one level."""
    return [i for i, c in enumerate(line) if c in "[#" and i >= AT - 1]


def _depths(rng: random.Random, n: int) -> list[int]:
    near = [MAX_NESTING - 1, MAX_NESTING, MAX_NESTING + 1]
    far = [int(10 ** rng.uniform(0, 5)) for _ in range(n)]
    return near + [min(d, 100_000) for d in far]


KINDS = ("brackets", "abs", "hashes", "indexed")


@pytest.mark.timeout(120)
@pytest.mark.parametrize("kind", KINDS)
def test_nesting_to_random_depths_is_read_or_refused_at_its_column(kind):
    rng = random.Random(f"nest-{kind}")
    for depth in _depths(rng, 4 if CI else 25):
        body, value = _nest(kind, depth)
        line = PREFIX + body
        text = f"#1=1\n{line}\nM2"
        openers = _openers(line)
        if len(openers) <= MAX_NESTING:
            program = parse(text)
            assert program.moves[0].end[0] == pytest.approx(value * 1e-3, abs=1e-12), depth
            continue
        with pytest.raises(GCodeError) as info:
            parse(text)
        error = info.value
        assert (error.line, error.code) == (2, "nesting"), (depth, str(error)[:200])
        assert error.column == openers[MAX_NESTING] + 1      # the one past the limit
        assert f"deeper than {MAX_NESTING}" in error.message
        assert len(str(error)) < 700           # the line is not printed back whole


@pytest.mark.timeout(120)
def test_mixed_nesting_counts_every_bracket_once():
    rng = random.Random("nest-mixed")
    for depth in _depths(rng, 4 if CI else 25):
        kinds = [rng.choice(("[", "ABS[", "[-", "SQRT[")) for _ in range(depth)]
        line = PREFIX + "".join(kinds) + "4" + "]" * depth
        expected = 4.0                 # the reference: the same functions, innermost first
        for opener in reversed(kinds):
            expected = {"[": expected, "ABS[": abs(expected), "[-": -expected,
                        "SQRT[": math.sqrt(expected) if expected >= 0 else math.nan}[opener]
        openers = _openers(line)
        if len(openers) <= MAX_NESTING:
            try:
                program = parse(line)
            except GCodeError as error:          # a square root of a negative value
                assert error.code == "bad-value" and math.isnan(expected), str(error)[:200]
                continue
            assert program.moves[0].end[0] == pytest.approx(expected * 1e-3, abs=1e-12)
            continue
        with pytest.raises(GCodeError) as info:
            parse(line)
        assert info.value.code == "nesting" and info.value.column == openers[MAX_NESTING] + 1


def test_a_run_of_signs_is_read_without_recursion():
    # each sign used to be a Python call: 5 000 of them overflowed the stack
    for n in (1, 2, 3, 999, 5000, 100_000):
        program = parse(f"{PREFIX}[" + "-" * n + "2]\nM2")
        assert program.moves[0].end[0] == pytest.approx((-2 if n % 2 else 2) * 1e-3)


def _long(rng: random.Random) -> list[int]:
    return [10, 301, 4300, 4301, 5000, *(int(10 ** rng.uniform(1, 5)) for _ in
                                         range(2 if CI else 12))]


@pytest.mark.timeout(120)
def test_numbers_of_any_length_are_refused_at_their_place():
    rng = random.Random("digits")
    for n in _long(rng):
        digits = "".join(rng.choice("123456789") for _ in range(n))
        cases = [
            # (program, line, column, code)
            (f"O{digits} sub\nO{digits} endsub\nM2", 1, 2, "bad-number"),
            (f"G1 F100\nN{digits} X1\nM2", 2, 1, "bad-number"),             # fast path
            (f"G1 F100\nN{digits} X[1]\nM2", 2, 1, "bad-number"),           # expression line
            (f"G1 F100\nN{digits} G1 X1 Y#1\nM2", 2, 1, "bad-number"),      # parameter line
            (f"G1 F100 X{digits}\nM2", 1, 9, "bad-number"),
            (f"G1 F100 X[1+{digits}]\nM2", 1, 13, "bad-number"),
            (f"#1={digits}\nM2", 1, 1, "bad-number"),
            (f"O1 repeat [{digits}]\nO1 endrepeat\nM2", 1, 12, "bad-number"),
        ]
        for text, line, column, code in cases:
            if n < 300 and "[" in text.splitlines()[line - 1] and "N" not in text:
                continue   # a number below 1e300 is a value in an expression
            if n < 300 and text.startswith("#1="):
                continue
            with pytest.raises(GCodeError) as info:
                parse(text)
            error = info.value
            assert (error.line, error.column, error.code) == (line, column, code), \
                (n, text[:40], str(error)[:200])
            assert len(str(error)) < 700


def test_o_words_and_n_numbers_up_to_nine_digits_are_read():
    program = parse("G1 F100\nO000123456789 sub\nG1 X2\nO123456789 endsub\n"
                    "N999999999 X1\nO123456789 call\nM2")
    assert [m.block_number for m in program.moves] == [999999999, None]
    assert [m.end[0] for m in program.moves] == pytest.approx([1e-3, 2e-3])


def test_a_long_line_is_shown_around_its_column():
    line = "(" + "a comment " * 40 + ") G1 X" + "[" * 300 + "1" + "]" * 300
    with pytest.raises(GCodeError) as info:
        parse(line)
    shown, caret = str(info.value).splitlines()[1:]
    at = caret.index("^")
    column = info.value.column
    # the character under the caret is the one at the error's column
    assert shown[at] == line[column - 1] and shown.startswith("    …") and \
        shown.endswith("…")
    assert info.value.source == line                 # the whole line stays on the error
