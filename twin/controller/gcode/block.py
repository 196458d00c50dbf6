"""One G-code block sorted by role, and the checks of its words (the interpreter's step 1).

``read_block`` sorts the words of a line: G/M codes into their modal groups (two of one
group is an error), value words into a table (a repeated letter is an error); letters of
axes this machine lacks are refused with a hint. The interpreter (``interpreter``) and its
motion (``motion``) read the values through ``at_least_zero`` and ``whole_number``, which
name the word in their errors.
"""

from __future__ import annotations

import math

from twin.controller.gcode.lexer import Word
from twin.controller.gcode.modal import CODES, GROUP_NAMES, Code, code_name
from twin.errors import GCodeError

__all__ = ["COINCIDENT", "OTHER_AXES", "VALUE_LETTERS", "WORKSPACE", "WRITTEN", "Z_HINT",
           "Block", "at_least_zero", "read_block", "whole", "whole_number"]

COINCIDENT = 1e-9
"""End points within 1 nm of the start are the start (m), far below the 0.2 µm encoder
resolution: ``G20 G2 X1 I…`` after ``G21 X25.4`` is a full circle although 1·25.4e-3 and
25.4·1e-3 differ in the last bit, and no arc is left whose sweep rounding could not tell
from a full turn. G0/G1 moves shorter than this produce no ``Move``."""

WORKSPACE = 1e3
"""Largest coordinate a program may reach (m); keeps every computation far from overflow."""

VALUE_LETTERS = frozenset("DFHIJLNPQRSTXYZ@^")
"""Letters of value words (K too, where Z is not refused)."""
OTHER_AXES = frozenset("ABCUVW")
WRITTEN = {"rapid": "G0", "line": "G1", "arc_cw": "G2", "arc_ccw": "G3", "cubic": "G5",
           "quadratic": "G5.1"}
"""How each motion is written, for messages."""


def whole(value: float) -> bool:
    return value == math.floor(value)


class Block:
    """The words of one block sorted by role, and its place for errors."""

    __slots__ = ("codes", "file", "line", "source", "values")

    def __init__(self, line: int, source: str, file: str | None = None):
        self.line = line
        self.source = source
        self.file = file
        self.codes: dict[str, tuple[Code, tuple[str, float], int]] = {}
        """Modal group → (table row, (letter, value) as written, column)."""
        self.values: dict[str, tuple[float, int]] = {}     # letter → (value, column)

    def error(self, column: int, message: str, code: str) -> GCodeError:
        return GCodeError(self.line, column, message, code=code, source=self.source,
                          file=self.file)

    def column(self, *letters: str) -> int:
        """Column of the first present word among ``letters`` (in line order), else 1."""
        columns = [self.values[letter][1] for letter in letters if letter in self.values]
        return min(columns, default=1)


Z_HINT = ("set controller.gcode.z = \"ignore\" to drop Z, or \"tool\" to run Z (pen) "
           "and M3/M5 (laser) as the tool on and off")


def read_block(words: list[Word], line: int, source: str, file: str | None, z_mode: str) -> Block:
    """Step 1: sort the words, refusing unknown, unsupported, conflicting, repeated ones."""
    block = Block(line, source, file)
    for letter, value, column in words:
        if letter == "G" or letter == "M":
            row = CODES.get((letter, value))
            if row is None:
                kind = "gcode" if letter == "G" else "mcode"
                raise block.error(column, f"unknown {letter} code {code_name(letter, value)}",
                                  f"unknown-{kind}")
            if row.refusal is not None:
                raise block.error(column, row.refusal, "unsupported")
            previous = block.codes.get(row.group)
            if previous is not None:
                raise block.error(column, f"two {GROUP_NAMES[row.group]} words in one block "
                                          f"({code_name(*previous[1])}, "
                                          f"{code_name(letter, value)})", "modal-conflict")
            block.codes[row.group] = (row, (letter, value), column)
        elif letter in VALUE_LETTERS:
            if letter in block.values:
                raise block.error(column, f"repeated {letter} word in one block",
                                  "repeated-word")
            if letter == "Z" and z_mode == "error":
                raise block.error(column, f"no Z axis on this machine ({Z_HINT})",
                                  "no-axis")
            block.values[letter] = (value, column)
        elif letter == "K":
            if z_mode == "error":
                raise block.error(column, "K word (arc centre along Z): no Z axis on this "
                                  f"machine ({Z_HINT})", "no-axis")
            if letter in block.values:
                raise block.error(column, "repeated K word in one block", "repeated-word")
            block.values[letter] = (value, column)
        elif letter in OTHER_AXES:
            raise block.error(column, f"no {letter} axis on this machine", "no-axis")
        else:
            raise block.error(column, f"unknown word {letter}", "unknown-word")
    return block


def at_least_zero(block: Block, letter: str, what: str) -> float:
    value, column = block.values[letter]
    if value < 0:
        raise block.error(column, f"{what} must be >= 0", "bad-value")
    return value


def whole_number(block: Block, letter: str, what: str, *, least: int = 0,
                  most: int | None = None) -> int:
    value, column = block.values[letter]
    if value < least or not whole(value) or (most is not None and value > most):
        span = f">= {least}" if most is None else f"from {least} to {most}"
        raise block.error(column, f"{what} must be a whole number {span}", "bad-value")
    return int(value)
