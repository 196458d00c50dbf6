"""Lines read once per shape (``twin.controller.gcode.shapes``) give exactly the items, and
the errors, of the reader that reads every line (``iter_items(..., fast=False)``, the
reference): the same floats, the same error at the same line and column."""

from __future__ import annotations

import io

import numpy as np
import pytest

from twin.controller.gcode import iter_items
from twin.controller.gcode.expr import read_statement
from twin.controller.gcode.parameters import Parameters
from twin.controller.gcode.shapes import Shapes
from twin.errors import GCodeError


def _read(text: str, fast: bool):
    try:
        return list(iter_items(io.StringIO(text), start=(0.01, -0.02), fast=fast)), None
    except GCodeError as error:
        return None, (error.line, error.column, error.code, error.message)


def _value(rng: np.random.Generator, depth: int = 0) -> str:
    """A random value of the LinuxCNC language: numbers, parameters, expressions; one in a
    few hundred is an error (a bad parameter number, an unset name, a domain error)."""
    number = f"{rng.normal(0, 20):.{rng.integers(0, 5)}f}"
    if rng.random() < 0.0004:
        return str(rng.choice(["#6000", "#[2.5]", "#<unset>", "[1/0]", "LN[-1]",
                               "[-2 ** 0.5]", "ACOS[2]", "[1 MOD 0]"]))
    kind = rng.integers(0, 9 if depth < 2 else 3)
    if kind == 0:
        return number
    if kind == 1:
        return f"#{rng.choice([1, 2, 3, 31, 4000])}"
    if kind == 2:
        return str(rng.choice(["#<width>", "#<_glob>", "#<x1>", "#<_x>"]))
    if kind == 3:
        op = str(rng.choice(["+", "-", "*", "GT", "AND", "EQ", "OR", "LE", "**"]))
        return f"[{_value(rng, depth + 1)} {op} {_value(rng, depth + 1)}]"
    if kind == 4:
        return f"[#{rng.choice([1, 2])} + {number}]"          # the commonest: an offset
    if kind == 5:
        name = str(rng.choice(["SIN", "COS", "ABS", "ROUND", "FIX", "FUP", "EXP"]))
        inner = _value(rng, depth + 1)
        return f"{name}[[{inner}] / 100]" if name == "EXP" else f"{name}[{inner}]"
    if kind == 6:
        return f"ATAN[{_value(rng, depth + 1)}]/[{_value(rng, depth + 1)}]"
    if kind == 7:
        return f"#[{rng.choice([1, 2, 3])} + 0]"                # indirection
    if kind == 8:
        return f"SQRT[ABS[{_value(rng, depth + 1)}]]"
    return f"-{_value(rng, depth + 1)}"


def _line(rng: np.random.Generator, n: int) -> str:
    """A line, most of them of a few shapes repeated with other digits."""
    shape = rng.integers(0, 8)
    x, y = rng.normal(0, 30, 2)
    if shape == 0:
        return f"G1 X[#1 + {x:.3f}] Y[#2 + {y:.3f}]"
    if shape == 1:
        return f"N{n} G1 X[#1+{x:.3f}]Y[#1 + {y:.4f}] F[#3 * {rng.integers(1, 9)}]"
    if shape == 2:
        return f"#{rng.choice([1, 2])} = [{_value(rng)} MOD 50]"
    if shape == 3:
        return f"G{rng.choice([0, 1])} X[{_value(rng)} MOD 90] Y[{_value(rng)} MOD 90]"
    if shape == 4:
        return f"#<width> = [{_value(rng)} MOD 9] X[#<width> * {x:.2f}]"
    if shape == 5:
        return f"G1 X#{rng.choice([1, 2, 31])} Y[{y:.3f} + #<_glob>]"
    if shape == 6:
        return str(rng.choice(["G91", "G90", "G20", "G21", "F[600 + #1]", "G1 X1 Y1",
                               "#<_glob> = 1.5", "#<x1> = 2 X#<x1>", "X[1 2.5] Y3",
                               "G1 X#<_x> Y[#<_y> + 1]", "#3 = [#3 + 1]"]))
    return f"X [ #1 + {x:.3f} ] Y [ #2 + {y:.3f} ]"


def _compare(seed: int) -> tuple[int, tuple | None]:
    """Read a random program both ways, assert the same; (lines read, error)."""
    rng = np.random.default_rng(seed)
    lines = ["G21 G90 G1 F1200", "#1 = 3", "#2 = -4", "#3 = 150", "#<_glob> = 2",
             "#<width> = 1", "#<x1> = 1"]
    lines += [_line(rng, n) for n in range(600)]
    text = "\n".join(lines) + "\nM2\n"
    fast, fast_error = _read(text, True)
    reference, reference_error = _read(text, False)
    assert fast_error == reference_error
    assert fast == reference
    read = len(lines) if fast_error is None else fast_error[0]
    return read, fast_error


@pytest.mark.parametrize("seed", range(30))
def test_compiled_shapes_read_as_the_reader_does(seed):
    _compare(seed)


def test_the_random_programs_run_long_enough_to_compare():
    """Many run to their end, the others end in an error far into the program."""
    ends = [_compare(seed) for seed in range(30)]
    assert sum(error is None for _, error in ends) >= 10
    assert sum(read for read, _ in ends) >= 30 * 200


@pytest.mark.parametrize("seed", range(10))
def test_every_line_of_a_program_the_same_way_up_to_its_error(seed):
    """Programs that end in an error somewhere: the same items before it, the same error."""
    rng = np.random.default_rng(1000 + seed)
    lines = ["G21 G90 G1 F1200", "#1 = 3", "#2 = 1"]
    for _ in range(300):
        lines.append(f"G1 X[#1 + {rng.normal(0, 9):.3f}] Y[#2 / {rng.integers(0, 40)}]")
    text = "\n".join(lines) + "\nM2\n"
    assert _read(text, True) == _read(text, False)


def _statement(shapes: Shapes, parameters: Parameters, code: str):
    lookup = lambda: lambda key, column: parameters.get(key)  # noqa: E731
    return shapes.read(code, 1, code, lookup)


def test_a_shape_is_compiled_the_second_time_and_then_gives_the_words():
    parameters = Parameters()
    parameters.set(1, 0.5)
    shapes = Shapes(parameters)
    first = _statement(shapes, parameters, "G1 X[#1 + 10.184] Y[#1 + 10.079]")
    assert first == read_statement("G1 X[#1 + 10.184] Y[#1 + 10.079]", 1, "",
                                   lambda key, column: parameters.get(key), parameters.exists)
    # the same shape with other digits: compiled, then N, G, X, Y, F values for fast_move
    assert _statement(shapes, parameters, "G1 X[#1 + 20.555] Y[#1 + 30.125]") == (
        None, 1.0, 0.5 + 20.555, 0.5 + 30.125, None)
    parameters.set(1, -2.0)
    assert _statement(shapes, parameters, "G0 X[#1 + 99.999] Y[#1 + 88.888]") == (
        None, 0.0, -2.0 + 99.999, -2.0 + 88.888, None)


def test_digits_that_are_not_numbers_of_the_reading_are_never_compiled():
    parameters = Parameters()
    parameters.set("x1", 4.0)
    parameters.set("x2", 7.0)
    shapes = Shapes(parameters)
    # "X#<x2> Y[#<x1> + 1]" and "X#<x1> Y[#<x2> + 1]" have one shape: compiled from the
    # first, the second would read x2 and x1
    for _ in range(3):
        got = _statement(shapes, parameters, "X#<x2> Y[#<x1> + 1]")
        assert got.words == [("X", 7.0, 1), ("Y", 5.0, 8)]
    got = _statement(shapes, parameters, "X#<x1> Y[#<x2> + 1]")
    assert got.words == [("X", 4.0, 1), ("Y", 8.0, 8)]
