"""Lines of the LinuxCNC language read once per shape.

Parameterised programs repeat a few line shapes thousands of times: ``G1 X[#1 + 10.184]
Y[#1 + 10.079]`` differs from the next line only in its digits. A line's *shape* is the line
with every digit written as ``0``; two lines of one shape have the same characters at the
same columns but for their digits, so ``twin.controller.gcode.expr`` reads them the same way:
the same words at the same columns, the same operations in the same order, only on other
numbers. The second time a shape is seen, the reader runs once over it in compiling mode
(:class:`_Compiler`, the same grammar code) and builds closures over the line's numbers; every
later line of the shape is its numbers (sliced where the shape has them) fed through them.

The compiled reading does the same float operations in the same order as the reader, so the
values are the same floats. Anything that would be an error (a division by zero, a parameter
number that is not whole, an unset named parameter, a value out of range) is not reported
here: the line is read again by ``read_statement``, which reports it with its column. A shape
whose digits are not all numbers of the reading (a ``#<name1>``, ``1.2.3``, an O-word label)
is never compiled.

A line whose words are only ``N``, ``G``, ``X``, ``Y`` and ``F``, without assignments, comes
back as the tuple ``(n, g, x, y, f)`` for the interpreter's fast path
(``Interpreter.fast_move``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from operator import itemgetter
from typing import Any

from twin.controller.gcode.expr import (
    MAX_VALUE,
    Assignment,
    Lookup,
    Statement,
    _Reader,
    read_statement,
)
from twin.controller.gcode.parameters import Parameters
from twin.controller.gcode.values import FUNCTIONS, BadValue, binary, parameter_index
from twin.errors import GCodeError

__all__ = ["FastWords", "Shapes"]

FastWords = tuple[float | None, float | None, float | None, float | None, float | None]
"""``(n, g, x, y, f)`` of a line of only those words (None: the word is absent)."""

Node = Callable[[list[float]], Any]
"""A compiled value: the line's numbers → value."""

_ZEROS = bytes.maketrans(b"123456789", b"000000000")
_RUN_SPANS = re.compile(r"[0-9.]+").finditer
_FAST_LETTERS = frozenset("NGXYF")


class _Fallback(Exception):
    """The compiled reading met something the reader reports: read the line again."""


class _Slot:
    """The line's ``i``-th number, negated if written with a minus sign."""

    __slots__ = ("i", "neg")

    def __init__(self, i: int, neg: bool):
        self.i, self.neg = i, neg


class _SlotIndex:
    """``#n`` with ``n`` the line's ``i``-th number."""

    __slots__ = ("i",)

    def __init__(self, i: int):
        self.i = i


class _Numbered:
    """``#n``, read: ``n`` the line's ``i``-th number."""

    __slots__ = ("i",)

    def __init__(self, i: int):
        self.i = i


def _index(v: float) -> int:
    """The parameter number ``#v`` names, as the reader takes it (``parameter_index``)."""
    number = parameter_index(v)
    if number is None:
        raise _Fallback
    return number


def _numbered(parameters: Parameters, v: float) -> float:
    """The value of numbered parameter ``#v``."""
    return parameters.get(_index(v))  # type: ignore[return-value]  # numbered: never None


def _fn(node: Any, parameters: Parameters | None = None) -> Node:
    """A node as a closure."""
    kind = type(node)
    if kind is _Numbered:
        i = node.i
        return lambda s: _numbered(parameters, s[i])   # type: ignore[arg-type]
    if kind is not _Slot:
        return node
    i = node.i
    if node.neg:
        return lambda s: -s[i]
    return lambda s: s[i]


class _Compiler(_Reader):
    """The reader in compiling mode: it returns nodes instead of values, and records where
    each number of the line is (``spans``, in the compacted line). Parameters are read
    through ``parameters`` when the nodes run."""

    def __init__(self, compact: str, columns: list[int] | None, line: int, source: str,
                 parameters: Parameters):
        super().__init__(compact, columns, line, source, _no_lookup, _no_exists)
        self.spans: list[tuple[int, int]] = []
        self.parameters = parameters

    def number(self) -> Any:
        start = self.pos
        super().number()
        sign = self.text[start]
        digits = start + 1 if sign == "+" or sign == "-" else start
        self.spans.append((digits, self.pos))
        return _Slot(len(self.spans) - 1, sign == "-")

    def negate(self, value: Any) -> Any:
        if type(value) is _Slot:
            return _Slot(value.i, not value.neg)
        f = _fn(value, self.parameters)
        return lambda s: -f(s)

    def index(self, value: Any, start: int) -> Any:
        if type(value) is _Slot and not value.neg:
            return _SlotIndex(value.i)
        f = _fn(value, self.parameters)
        return lambda s: _index(f(s))

    def read(self, key: Any, column: int) -> Any:
        if type(key) is _SlotIndex:              # #1: the commonest
            return _Numbered(key.i)
        get = self.parameters.get
        index = key if callable(key) else None

        def named(s: list[float]) -> float:
            value = get(key if index is None else index(s))
            if value is None:
                raise _Fallback
            return value
        return named

    def exists_value(self, name: str) -> Any:
        has = self.parameters.exists
        return lambda s: 1.0 if has(name) else 0.0

    def atan(self, y: Any, x: Any) -> Any:
        fy, fx = _fn(y, self.parameters), _fn(x, self.parameters)
        return lambda s: math.degrees(math.atan2(fy(s), fx(s)))

    def call(self, name: str, argument: Any, start: int) -> Any:
        f, domain, _ = FUNCTIONS[name]
        fa = _fn(argument, self.parameters)

        def call(s: list[float]) -> float:
            x = fa(s)
            if domain is not None and not domain(x):
                raise _Fallback
            return float(f(x))
        return call

    def binary(self, op: str, a: Any, b: Any, at: int) -> Any:
        if op == "+" and type(b) is _Slot and not b.neg:
            j = b.i
            if type(a) is _Numbered:            # the commonest: [#1 + 10.184]
                i, parameters = a.i, self.parameters

                def offset(s: list[float]) -> float:
                    r = _numbered(parameters, s[i]) + s[j]
                    if -1e300 < r < 1e300:
                        return r
                    raise _Fallback
                return offset
            fa = _fn(a, self.parameters)

            def add(s: list[float]) -> float:
                r = fa(s) + s[j]
                if -1e300 < r < 1e300:
                    return r
                raise _Fallback
            return add
        fa, fb = _fn(a, self.parameters), _fn(b, self.parameters)
        return lambda s: binary(op, fa(s), fb(s))

    def word_value(self, letter: str, value: Any, start: int) -> Any:
        return value            # checked when the line runs (_Shape.run)

    def oword(self) -> Any:
        raise _Fallback    # control statements are read every time


def _no_lookup(key: int | str, column: int) -> float:
    raise AssertionError("a compiling reader reads no parameter")


def _no_exists(name: str) -> bool:
    raise AssertionError("a compiling reader reads no parameter")


class _Shape:
    """One compiled line shape."""

    __slots__ = ("assignments", "fast", "numbers", "words")

    def __init__(self, statement: Statement, parameters: Parameters,
                 spans: list[tuple[int, int]]):
        # the numbers are where they were in the line compiled: one C call takes them all
        if len(spans) == 1:
            (a, b), = spans
            self.numbers: Callable[[str], Any] = lambda code: (code[a:b],)
        else:
            self.numbers = itemgetter(*(slice(a, b) for a, b in spans)) if spans else \
                (lambda code: ())
        self.words = [(letter, _fn(node, parameters), column)
                      for letter, node, column in statement.words]
        self.assignments = [(key if isinstance(key, str) else _fn_key(key),
                             _fn(node, parameters), column)
                            for key, node, column in statement.assignments]
        letters = [letter for letter, _, _ in statement.words]
        self.fast: tuple[Node | None, ...] | None = None
        if (not self.assignments and set(letters) <= _FAST_LETTERS
                and len(set(letters)) == len(letters) and ("X" in letters or "Y" in letters)):
            by = {letter: f for letter, f, _ in self.words}
            self.fast = tuple(by.get(letter) for letter in "NGXYF")

    def run(self, code: str) -> Statement | FastWords:
        s = [*map(float, self.numbers(code))]
        if self.fast is not None:    # fast_move checks the ranges
            n, g, x, y, f = self.fast
            return (None if n is None else n(s), None if g is None else g(s),
                    None if x is None else x(s), None if y is None else y(s),
                    None if f is None else f(s))
        words = []
        for letter, f, column in self.words:
            v = f(s)
            if not -MAX_VALUE < v < MAX_VALUE:
                raise _Fallback
            words.append((letter, v, column))
        assignments = [Assignment(key if isinstance(key, str) else key(s), f(s), column)
                       for key, f, column in self.assignments]
        return Statement(words, assignments, None)


def _fn_key(key: Any) -> Callable[[list[float]], int]:
    """An assignment's parameter number as a closure."""
    if type(key) is not _SlotIndex:
        return key
    i = key.i
    return lambda s: _index(s[i])


def _compile(code: str, line: int, source: str, parameters: Parameters) -> _Shape | None:
    """The shape of ``code`` compiled, or None when it cannot be (see the module doc)."""
    if " " in code or "\t" in code:
        columns = [index + 1 for index, char in enumerate(code) if char != " " and char != "\t"]
        compact = code.replace(" ", "").replace("\t", "")
    else:
        columns, compact = None, code
    compiler = _Compiler(compact, columns, line, source, parameters)
    try:
        statement = compiler.statement()
    except (_Fallback, GCodeError):
        return None
    spans = []
    for start, end in compiler.spans:       # each number in the line as written
        a = start if columns is None else columns[start] - 1
        b = end if columns is None else columns[end - 1]
        if code[a:b] != compact[start:end]:
            return None                     # blanks inside a number
        spans.append((a, b))
    if spans != [m.span() for m in _RUN_SPANS(code)]:
        return None                         # digits that are not numbers of the reading
    return _Shape(statement, parameters, spans)


_SEEN = object()
"""A shape seen once: compiled when seen again."""


class Shapes:
    """The compiled shapes of one program's reading (at most ``size`` kept), reading its
    ``parameters``."""

    def __init__(self, parameters: Parameters, size: int = 4096):
        self.parameters = parameters
        self._known: dict[bytes, Any] = {}
        self._size = size

    def read(self, code: str, line: int, source: str, lookup: Callable[[], Lookup]
             ) -> Statement | FastWords:
        """What ``read_statement`` returns for the line, or, for a line of only N, G, X, Y
        and F words, their values ``(n, g, x, y, f)``. ``lookup()`` gives the parameter
        lookup ``read_statement`` needs (made only when the line is read the general way)."""
        key = code.encode().translate(_ZEROS)     # bytes: 10x faster than str.translate
        known = self._known
        shape = known.get(key)
        if shape is None:
            if key not in known:
                if len(known) >= self._size:
                    known.clear()
                known[key] = _SEEN
            return read_statement(code, line, source, lookup(), self.parameters.exists)
        if shape is _SEEN:
            shape = known[key] = _compile(code, line, source, self.parameters)
            if shape is None:
                return read_statement(code, line, source, lookup(), self.parameters.exists)
        try:
            return shape.run(code)
        except (_Fallback, BadValue, ArithmeticError, ValueError):
            return read_statement(code, line, source, lookup(), self.parameters.exists)
