"""The reader's fast path for the commonest CAM line gives exactly the items, and the errors,
of the general path (``iter_items(..., fast=False)``, the reference)."""

from __future__ import annotations

import io

import numpy as np
import pytest

from twin.controller.gcode import FAST_LINE, Interpreter, Move, ReaderOptions, iter_items
from twin.errors import GCodeError


def _read(text: str, fast: bool, options=None):
    try:
        return list(iter_items(io.StringIO(text), start=(0.01, -0.02), fast=fast,
                               options=options)), None
    except GCodeError as error:
        return None, (error.line, error.column, error.code, error.message)


def _line(rng: np.random.Generator) -> str:
    words = []
    if rng.random() < 0.2:
        words.append(f"N{rng.integers(0, 99999):0{rng.integers(1, 6)}d}")
    if rng.random() < 0.5:
        words.append(str(rng.choice(["G0", "G1", "G00", "G01", "g1", "G2", "G3", "G10"])))
    for letter, scale in (("X", 100), ("Y", 100)):
        if rng.random() < 0.8:
            value = rng.normal(0, scale) * (1e6 if rng.random() < 0.01 else 1)
            text = str(rng.choice([f"{value:.3f}", f"{value:.4f}", f"{value:.0f}.",
                                   f"{value:+.2f}", f"{abs(value) % 1:.3f}"[1:]]))
            words.append(letter.lower() if rng.random() < 0.1 else letter + text)
            if words[-1] == letter.lower():
                words[-1] += text
    if rng.random() < 0.15:
        words.append(f"F{rng.choice([0, rng.integers(1, 5000)])}")
    separator = str(rng.choice([" ", "", "  "]))
    return separator.join(words)


MODES = ["G90", "G91", "G20", "G21", "G10 L2 P1 X3 Y-4", "G92 X0 Y0", "G92.1", "G18",
         "G17", "G2 X1 Y1 I1 J0", "G80", "F0", "F600", "G55", "G54", "X0 Y0", "(comment)", ""]


def _block(interpreter: Interpreter, text: str, line: int, fast: bool):
    """One line through one path: its items, or its error."""
    try:
        found = FAST_LINE.fullmatch(text) if fast else None
        result = interpreter.fast_line(found, line) if found is not None else None
        if result is None:
            return interpreter.execute(text, line=line)
        return () if result is True else (result,)
    except GCodeError as error:
        return (error.line, error.column, error.code, error.message)


@pytest.mark.parametrize("seed", range(40))
def test_the_fast_path_is_the_general_path_line_by_line(seed):
    """Two interpreters read the same lines, one by the fast path where it matches: every
    line gives the same items or the same error, and the states stay equal (a bad block
    changes nothing on either path)."""
    rng = np.random.default_rng(seed)
    fast, reference = Interpreter(start=(0.01, -0.02)), Interpreter(start=(0.01, -0.02))
    taken = moves = 0
    for line in range(1, 1501):
        text = _line(rng) if rng.random() < 0.85 else str(rng.choice(MODES))
        if line == 1:
            text = "G21 G90 G1 F1200"
        got, want = _block(fast, text, line, True), _block(reference, text, line, False)
        assert got == want, text
        assert (fast.position, fast.state) == (reference.position, reference.state)
        taken += FAST_LINE.fullmatch(text) is not None and isinstance(want, tuple) \
            and not (want and isinstance(want[0], int))
        moves += sum(isinstance(item, Move) for item in want if not isinstance(item, int))
    assert taken > 200 and moves > 200


@pytest.mark.parametrize("seed", range(10))
def test_the_fast_path_is_the_general_path_on_whole_programs(seed):
    rng = np.random.default_rng(100 + seed)
    lines = ["G21 G90 G1 F1200"]
    x = y = 0.0
    for n in range(2000):
        x += rng.normal(0, 2)
        y += rng.normal(0, 2)
        lines.append(str(rng.choice([f"G1 X{x:.3f} Y{y:.3f}", f"X{x:.4f}Y{y:.4f}",
                                     f"N{n} G01 X{x:.3f} Y{y:.3f} F{rng.integers(100, 900)}",
                                     f"G0 X{x:.3f}", "G91 G1 X0.5 Y-0.5\nG90",
                                     "G2 X[#<_x> + 2] Y#<_y> R1.5\nG1"])))
    text = "\n".join(lines)
    fast, fast_error = _read(text, True)
    reference, reference_error = _read(text, False)
    assert fast_error == reference_error
    assert fast == reference and len(fast) > 1500


def test_the_fast_path_keeps_the_tool_and_the_offsets():
    text = ("G21 G90 F600\nG10 L2 P1 X5 Y5\nG1 X1 Y1\nM3 S100\nG1 Z-1\nX2 Y2\nG1 Z1\n"
            "X3 Y3\nM2")
    options = ReaderOptions(z="tool")
    assert _read(text, True, options) == _read(text, False, options)
