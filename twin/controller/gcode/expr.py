"""The LinuxCNC language on one line: parameters, expressions, assignments and O-words.

A line that holds none of ``#``, ``[`` or ``O`` goes through the fast word lexer
(``twin.controller.gcode.lexer``); every other line is read here, as LinuxCNC's
``read_items`` reads it, with the parameters as they were before the line:

* spaces and tabs are not significant outside comments (``X [ 1 + 2 ]`` = ``X[1+2]``);
* a value is a number, ``[expression]``, ``#n``, ``##n``, ``#[expr]``, ``#<name>``, a unary
  function (``SIN[30]``, ``ATAN[1]/[2]``, ``EXISTS[#<name>]``) or one of these after a
  ``+``/``-`` sign;
* binary operators by precedence, each level left-associative as in LinuxCNC:
  ``**`` > ``* / MOD`` > ``+ -`` > ``EQ NE GT GE LT LE`` > ``AND OR XOR``;
* ``#n = value`` and ``#<name> = value`` assign, taking effect after the whole line is read
  (``#1=2 X#1`` uses the old ``#1``), and only if the block runs;
* ``O<name> keyword [args]`` or ``O123 keyword [args]`` is a control statement: nothing but
  a comment may share its line;
* ``@`` (distance) and ``^`` (angle, degrees) are polar coordinates, words like X and Y.

Bounds: brackets, function arguments and ``#`` references nest at most ``MAX_NESTING``
(100) deep together, far above what a real program writes (a handful) or what fits on a
line of LinuxCNC (at most 255 characters); deeper, the line is refused (``nesting``) at the
bracket or ``#`` that went past the limit. A number is a float of any length: one of 1e300
or more is refused at its place (``bad-number``), and an O-word number must be below 1e9.

Angles of the trigonometric functions are in degrees, as in LinuxCNC. ``EQ`` and ``NE``
compare within ``EQUAL_TOLERANCE`` (LinuxCNC's ``TOLERANCE_EQUAL``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import NamedTuple

from twin.controller.gcode.lexer import MAX_VALUE, Word
from twin.controller.gcode.values import (
    EQUAL_TOLERANCE,
    FUNCTIONS,
    BadValue,
    binary,
    parameter_index,
)
from twin.errors import GCodeError

__all__ = ["EQUAL_TOLERANCE", "KEYWORDS", "MAX_NESTING", "Assignment", "OWord", "Statement",
           "read_statement"]

MAX_NESTING = 100
"""Most brackets, function arguments and ``#`` references open at once on one line."""

MAX_NUMBER = 1e300
"""Magnitude from which a number written in a program is refused (the binary operators
refuse such results too)."""

KEYWORDS = ("sub", "endsub", "call", "do", "while", "endwhile", "if", "elseif", "else",
            "endif", "break", "continue", "return", "repeat", "endrepeat")
"""O-word keywords."""

_ARGUMENTS = {"call": (0, 30), "endsub": (0, 1), "return": (0, 1), "while": (0, 1),
              "if": (1, 1), "elseif": (1, 1), "repeat": (1, 1)}
"""Keyword → (fewest, most) bracketed arguments; the rest take none. ``while`` closing a
``do`` and opening a loop both need one: checked by the runner, which knows which it is."""


class Assignment(NamedTuple):
    """``#target = value`` of one line."""

    target: int | str
    """Parameter number, or lower-case name without spaces."""
    value: float
    column: int


class OWord(NamedTuple):
    """A control statement: ``O<label> keyword [arguments]``."""

    label: str
    """``"<name>"`` (lower case) or the number as written without leading zeros."""
    keyword: str
    arguments: tuple[float, ...]
    column: int
    """Column of the ``O``."""


class Statement(NamedTuple):
    """What one line says."""

    words: list[Word]
    assignments: list[Assignment]
    oword: OWord | None


Lookup = Callable[[int | str, int], float]
"""Reads a parameter: (number or name, column) → value; raises ``GCodeError`` if unset."""
Exists = Callable[[str], bool]


# ATAN (two arguments) and EXISTS (a parameter name) are read apart.
_FUNCTION_NAMES = sorted((*FUNCTIONS, "ATAN", "EXISTS"), key=len, reverse=True)

# Binary operators: spelling → precedence (LinuxCNC's ``precedence``), longest first.
_OPERATORS = (("**", 6), ("*", 5), ("/", 5), ("MOD", 5), ("+", 4), ("-", 4), ("EQ", 3),
              ("NE", 3), ("GT", 3), ("GE", 3), ("LT", 3), ("LE", 3), ("AND", 2),
              ("XOR", 2), ("OR", 2))
_DIGITS = "0123456789"
_BY_FIRST: dict[str, tuple[tuple[str, int], ...]] = {}
for _spelling, _precedence in _OPERATORS:
    _BY_FIRST[_spelling[0]] = (*_BY_FIRST.get(_spelling[0], ()), (_spelling, _precedence))
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)").match
_NUMBER_START = frozenset("+-.0123456789")
_NUMBER_BODY = frozenset(".0123456789")



class _Reader:
    """One compacted line (blanks removed, upper case) and the columns of its characters."""

    __slots__ = ("at", "columns", "depth", "end", "exists", "line", "lookup", "pos", "source",
                 "text")

    def __init__(self, text: str, columns: list[int] | None, line: int, source: str,
                 lookup: Lookup, exists: Exists):
        self.text = text + "\0"            # a sentinel: no bounds checks while reading
        self.end = len(text)
        self.columns = columns              # None: no blanks were removed
        self.line = line
        self.source = source
        self.lookup = lookup
        self.exists = exists
        self.pos = 0
        self.depth = 0                      # brackets and '#'s open (MAX_NESTING)
        self.at = 0                         # where the word being read begins

    def column(self, pos: int | None = None) -> int:
        at = min(self.pos if pos is None else pos, max(self.end - 1, 0))
        if self.columns is None:
            return at + 1
        return self.columns[at] if self.columns else 1

    def error(self, message: str, code: str = "syntax", pos: int | None = None) -> GCodeError:
        return GCodeError(self.line, self.column(pos), message, code=code, source=self.source)

    def peek(self) -> str:
        return self.text[self.pos]

    # -- values -----------------------------------------------------------------------
    def number(self) -> float:
        found = _NUMBER(self.text, self.pos)
        if found is None:
            raise self.error("expected a number, a [expression], a #parameter or a function",
                             "bad-number")
        value = float(found.group())
        if not -MAX_NUMBER < value < MAX_NUMBER:
            digits = sum(c in _DIGITS for c in found.group())
            # a word's own number is placed at its letter, as the lexer places it
            raise self.error(f"number of {digits} digits is out of range (|value| < "
                             f"{MAX_NUMBER:g})", "bad-number",
                             self.at if self.depth == 0 else None)
        self.pos = found.end()
        return value

    def nest(self, start: int) -> None:
        """One more bracket or '#' opens at ``start``: refused past ``MAX_NESTING``."""
        self.depth += 1
        if self.depth > MAX_NESTING:
            raise self.error(f"brackets, functions and '#' nest deeper than {MAX_NESTING} "
                             "levels", "nesting", start)

    def value(self) -> float:
        text, pos = self.text, self.pos
        char = text[pos]
        if (char == "+" or char == "-") and text[pos + 1] not in _NUMBER_BODY:
            negative = False            # a run of signs: read in a loop, not recursively
            while (char == "+" or char == "-") and text[pos + 1] not in _NUMBER_BODY:
                negative ^= char == "-"
                pos += 1
                char = text[pos]
            self.pos = pos
            value = self.value()
            return self.negate(value) if negative else value
        if char in _NUMBER_START:
            return self.number()
        if char == "[":
            return self.expression()
        if char == "#":
            return self.parameter()
        if "A" <= char <= "Z":
            return self.function()
        return self.number()

    def parameter_key(self) -> int | str:
        """After a ``#``: the number or ``<name>`` it refers to."""
        start = self.pos
        self.pos += 1  # the '#'
        if self.pos >= self.end:
            raise self.error("'#' without a parameter number or <name>", pos=start)
        self.nest(start)
        if self.peek() == "<":
            close = self.text.find(">", self.pos)
            if close < 0:
                raise self.error("named parameter '#<' without its closing '>'", pos=start)
            name = self.text[self.pos + 1:close].lower()
            if not name:
                raise self.error("empty parameter name '#<>'", pos=start)
            self.pos = close + 1
            self.depth -= 1
            return name
        index = self.index(self.value(), start)
        self.depth -= 1
        return index

    def parameter(self) -> float:
        start = self.pos
        return self.read(self.parameter_key(), self.column(start))

    # -- what a value means (``twin.controller.gcode.shapes`` compiles the same reading) --
    def negate(self, value: float) -> float:
        return -value

    def index(self, value: float, start: int) -> int:
        """The parameter number ``#value`` names."""
        index = parameter_index(value)
        if index is None:
            index = math.floor(value + 1e-4)
            if abs(value - index) > 1e-4:
                raise self.error(f"parameter number {value:.12g} is not a whole number",
                                 "bad-value", start)
            raise self.error(f"parameter number {index} is out of range (1 to 5601)",
                             "out-of-range", start)
        return index

    def read(self, key: int | str, column: int) -> float:
        return self.lookup(key, column)

    def exists_value(self, name: str) -> float:
        return 1.0 if self.exists(name) else 0.0

    def atan(self, y: float, x: float) -> float:
        return math.degrees(math.atan2(y, x))

    def call(self, name: str, argument: float, start: int) -> float:
        f, domain, message = FUNCTIONS[name]
        if domain is not None and not domain(argument):
            raise self.error(f"{message} ({name}[{argument:.12g}])", "bad-value", start)
        return float(f(argument))

    def word_value(self, letter: str, value: float, start: int) -> float:
        if not -MAX_VALUE < value < MAX_VALUE:
            raise self.error(f"{letter} value {value:.12g} is out of range (|value| < "
                             f"{MAX_VALUE:g})", "bad-number", start)
        return value

    def function(self) -> float:
        start, text = self.pos, self.text
        name = next((n for n in _FUNCTION_NAMES if text.startswith(n, start)), None)
        if name is None:
            raise self.error(f"unknown word or function at '{text[start:start + 6]}'",
                             "unknown-word")
        self.pos += len(name)
        if self.peek() != "[":
            raise self.error(f"{name} needs its argument in brackets: {name}[...]")
        if name == "EXISTS":
            self.pos += 1
            if self.peek() != "#" or self.pos + 1 >= len(text) or text[self.pos + 1] != "<":
                raise self.error("EXISTS needs a named parameter: EXISTS[#<name>]")
            key = self.parameter_key()
            self.expect("]")
            return self.exists_value(str(key))
        argument = self.expression()
        if name == "ATAN":
            if self.peek() != "/":
                raise self.error("ATAN takes two arguments: ATAN[y]/[x]")
            self.pos += 1
            if self.peek() != "[":
                raise self.error("ATAN takes two arguments: ATAN[y]/[x]")
            return self.atan(argument, self.expression())
        return self.call(name, argument, start)

    def expect(self, char: str) -> None:
        if self.peek() != char:
            raise self.error(f"expected '{char}'")
        self.pos += 1

    def operator(self) -> tuple[str, int] | None:
        text, pos = self.text, self.pos
        for spelling, precedence in _BY_FIRST.get(text[pos], ()):
            if text.startswith(spelling, pos):
                return spelling, precedence
        return None

    def expression(self) -> float:
        """``[ value (operator value)* ]``, evaluated as LinuxCNC does: a stack of operands
        and operators, reduced while the next operator binds no tighter than the last."""
        start = self.pos
        self.expect("[")
        self.nest(start)
        values = [self.value()]
        operators: list[tuple[str, int, int]] = []
        while True:
            if self.peek() == "]":
                self.pos += 1
                while operators:
                    self.reduce(values, operators)
                self.depth -= 1
                return values[0]
            found = self.operator()
            if found is None:
                if self.pos >= self.end:
                    raise self.error("expression '[' is not closed on this line", pos=start)
                raise self.error("expected an operator or ']'")
            spelling, precedence = found
            while operators and operators[-1][1] >= precedence:
                self.reduce(values, operators)
            operators.append((spelling, precedence, self.pos))
            self.pos += len(spelling)
            values.append(self.value())

    def reduce(self, values: list[float], operators: list[tuple[str, int, int]]) -> None:
        spelling, _, at = operators.pop()
        right = values.pop()
        left = values.pop()
        values.append(self.binary(spelling, left, right, at))

    def binary(self, op: str, a: float, b: float, at: int) -> float:
        try:
            return binary(op, a, b)
        except BadValue as bad:
            raise self.error(str(bad), "bad-value", at) from None

    # -- the line ---------------------------------------------------------------------
    def oword(self) -> OWord:
        start = self.pos
        self.pos += 1  # the 'O'
        if self.peek() == "<":
            close = self.text.find(">", self.pos)
            if close < 0:
                raise self.error("O-word name '<' without its closing '>'", pos=start)
            label = self.text[self.pos:close + 1].lower()
            self.pos = close + 1
        else:
            digits = self.pos
            while self.peek() and self.peek() in _DIGITS:
                self.pos += 1
            if digits == self.pos:
                raise self.error("O-word needs a number or a <name> as its label", pos=start)
            label = self.text[digits:self.pos].lstrip("0") or "0"   # no int(): any length
            if len(label) > 9:
                raise self.error(f"O-word number of {len(label)} digits is out of range "
                                 f"(below {MAX_VALUE:g})", "bad-number", start + 1)
        rest = self.text[self.pos:self.end]
        keyword = next((k for k in sorted(KEYWORDS, key=len, reverse=True)
                        if rest.startswith(k.upper())), None)
        if keyword is None:
            raise self.error("O-word without a keyword (sub, endsub, call, do, while, "
                             "endwhile, if, elseif, else, endif, break, continue, return, "
                             "repeat, endrepeat)", "unknown-word", start)
        self.pos += len(keyword)
        arguments = []
        while self.peek() == "[":
            arguments.append(self.expression())
        if self.pos < self.end:
            raise self.error(f"unexpected text after 'O{label} {keyword}': nothing but a "
                             "comment may follow a control statement")
        fewest, most = _ARGUMENTS.get(keyword, (0, 0))
        if not fewest <= len(arguments) <= most:
            wanted = (f"{fewest}" if fewest == most else f"{fewest} to {most}")
            raise self.error(f"'{keyword}' takes {wanted} bracketed argument"
                             f"{'' if most == 1 else 's'}, got {len(arguments)}",
                             "missing-word" if len(arguments) < fewest else "unused-word",
                             start)
        return OWord(label, keyword, tuple(arguments), self.column(start))

    def statement(self) -> Statement:
        words: list[Word] = []
        assignments: list[Assignment] = []
        text, end = self.text, self.end
        if self.peek() == "N":  # a block number may precede an O-word
            start = self.at = self.pos
            self.pos += 1
            words.append(("N", self.word_value("N", self.number(), start),
                          self.column(start)))
        if self.peek() == "O":
            return Statement(words, [], self.oword())
        while self.pos < end:
            char = text[self.pos]
            start = self.at = self.pos
            if char == "#":
                key = self.parameter_key()
                if self.peek() != "=":
                    raise self.error("a parameter on its own: assign it (#1=...) or use it "
                                     "as a word's value (X#1)", pos=start)
                self.pos += 1
                assignments.append(Assignment(key, self.value(), self.column(start)))
            elif "A" <= char <= "Z" or char == "@" or char == "^":
                if char == "O":
                    raise self.error("an O-word must begin its line (after an N word)",
                                     pos=start)
                self.pos += 1
                if self.pos >= end:
                    raise self.error(f"{char} word without a value", "bad-number", start)
                value = self.value()
                words.append((char, self.word_value(char, value, start), self.column(start)))
            elif char in "+-.0123456789":
                raise self.error("number without a letter before it")
            else:
                raise self.error(f"unexpected character {char!r}")
        return Statement(words, assignments, None)


def read_statement(code: str, line: int, source: str, lookup: Lookup,
                   exists: Exists) -> Statement:
    """Read one line of the LinuxCNC language.

    Parameters
    ----------
    code : str
        The line with comments blanked and in upper case (``lexer.clean``); columns match
        ``source``.
    line : int
        1-based line number, for errors.
    source : str
        The line as written, for errors.
    lookup : callable
        ``lookup(key, column)``: the value of parameter ``key`` (number or lower-case name).
    exists : callable
        ``exists(name)``: whether a named parameter is set.

    Returns
    -------
    Statement
        Its words (values evaluated), its assignments and its O-word, if any.

    Raises
    ------
    GCodeError
        At the first character or operation that is wrong, with its column.
    """
    if " " in code or "\t" in code:
        columns = [index + 1 for index, char in enumerate(code) if char != " " and char != "\t"]
        compact = code.replace(" ", "").replace("\t", "")
    else:
        columns, compact = None, code
    reader = _Reader(compact, columns, line, source, lookup, exists)
    return reader.statement()
