"""The arithmetic of the LinuxCNC language: its functions, its binary operators and the
parameter a number names, as LinuxCNC computes them (``twin.controller.gcode.expr`` reads the
language, ``twin.controller.gcode.shapes`` compiles lines of it; both compute with these).

Angles of the trigonometric functions are in degrees, as in LinuxCNC.
"""

from __future__ import annotations

import math
from collections.abc import Callable

__all__ = ["EQUAL_TOLERANCE", "FUNCTIONS", "BadValue", "binary", "parameter_index"]

EQUAL_TOLERANCE = 1e-4
"""``EQ``/``NE`` treat values closer than this as equal (LinuxCNC's ``TOLERANCE_EQUAL``)."""


def _degrees(f: Callable[[float], float]) -> Callable[[float], float]:
    return lambda x: f(math.radians(x))


def _round(x: float) -> float:
    return float(math.floor(x + 0.5) if x >= 0.0 else math.ceil(x - 0.5))


FUNCTIONS: dict[str, tuple[Callable[[float], float], Callable[[float], bool] | None, str]] = {
    "ABS": (abs, None, ""),
    "ACOS": (lambda x: math.degrees(math.acos(x)), lambda x: -1.0 <= x <= 1.0,
             "ACOS argument must be within [-1, 1]"),
    "ASIN": (lambda x: math.degrees(math.asin(x)), lambda x: -1.0 <= x <= 1.0,
             "ASIN argument must be within [-1, 1]"),
    "COS": (_degrees(math.cos), None, ""),
    "SIN": (_degrees(math.sin), None, ""),
    "TAN": (_degrees(math.tan), None, ""),
    "EXP": (math.exp, lambda x: x < 700.0, "EXP argument too large"),
    "LN": (math.log, lambda x: x > 0.0, "LN of a value <= 0"),
    "SQRT": (math.sqrt, lambda x: x >= 0.0, "SQRT of a negative value"),
    "FIX": (lambda x: float(math.floor(x)), None, ""),
    "FUP": (lambda x: float(math.ceil(x)), None, ""),
    "ROUND": (_round, None, ""),
}
"""Unary functions: name → (f, domain check or None, message when outside the domain)."""


class BadValue(ValueError):
    """An operation's operands are outside its domain (the message says how)."""


def binary(op: str, a: float, b: float) -> float:
    """``a op b`` as LinuxCNC computes it.

    Raises
    ------
    BadValue
        Division or MOD by zero, a power without a real value, a result out of range.
    """
    if op == "+":
        result = a + b
    elif op == "-":
        result = a - b
    elif op == "*":
        result = a * b
    elif op == "/":
        if b == 0.0:
            raise BadValue("division by zero")
        result = a / b
    elif op == "MOD":
        if b == 0.0:
            raise BadValue("MOD by zero")
        result = math.fmod(a, b)
        if result < 0.0:
            result += abs(b)
    elif op == "**":
        if a < 0.0 and b != math.floor(b):
            raise BadValue("a negative number raised to a non-integer power")
        if a == 0.0 and b < 0.0:
            raise BadValue("zero raised to a negative power")
        try:
            result = math.pow(a, b)
        except OverflowError:
            raise BadValue("power overflows") from None
    elif op == "EQ":
        result = float(abs(a - b) < EQUAL_TOLERANCE)
    elif op == "NE":
        result = float(abs(a - b) >= EQUAL_TOLERANCE)
    elif op == "GT":
        result = float(a > b)
    elif op == "GE":
        result = float(a >= b)
    elif op == "LT":
        result = float(a < b)
    elif op == "LE":
        result = float(a <= b)
    elif op == "AND":
        result = float(a != 0.0 and b != 0.0)
    elif op == "OR":
        result = float(a != 0.0 or b != 0.0)
    else:  # XOR
        result = float((a != 0.0) != (b != 0.0))
    if not math.isfinite(result) or abs(result) >= 1e300:
        raise BadValue(f"{op} gives a value out of range")
    return result


def parameter_index(value: float) -> int | None:
    """The parameter number ``#value`` names (a whole number within 1e-4), or None when it
    names none (not whole, or outside 1 to 5601)."""
    index = math.floor(value + 1e-4)
    if abs(value - index) > 1e-4 or not 1 <= index <= 5601:
        return None
    return index
