"""How deeply a JSON or TOML text nests, found without parsing it.

Python's ``json`` and ``tomllib`` parse nested arrays and tables by recursion, and so do the
functions that walk what they return (``copy.deepcopy``, a config's flattening): a file that
nests a few thousand levels ends in a ``RecursionError`` and a traceback. These scanners read
the text once, with a small tokenizer that skips strings and comments, and report the first
place where the nesting passes a limit, before anything is parsed. The limit, ``MAX_DEPTH``,
is far above anything xy-twin writes or reads (a machine file nests 4 levels, an
identification log 4, a line of a trial log 4).

A leaf of the house (the standard library only): the machine files' loader
(``twin.config``) and the JSON records' (``twin.system.jsonio``, imported at start-up) both
use it.
"""

from __future__ import annotations

import re
from typing import NamedTuple

__all__ = ["MAX_DEPTH", "Deep", "json_too_deep", "toml_too_deep"]

MAX_DEPTH = 64
"""Most levels of arrays and tables (objects) open at once in a JSON or TOML text."""


class Deep(NamedTuple):
    """Where a text first nests deeper than the limit."""

    line: int
    """1-based line."""
    column: int
    """1-based column of the bracket (or dot of a key) that went past the limit."""
    key: str
    """TOML: the table and key being read (shortened); JSON: ``""``."""


def _place(text: str, pos: int, key: str = "") -> Deep:
    line = text.count("\n", 0, pos) + 1
    return Deep(line, pos - (text.rfind("\n", 0, pos) + 1) + 1, key)


_JSON_TOKEN = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"|[\[\]{}]')


def json_too_deep(text: str, limit: int = MAX_DEPTH) -> Deep | None:
    """The place where ``text`` (JSON) first nests more than ``limit`` arrays and objects,
    or None. Strings are skipped, so brackets inside them do not count. Linear in the
    text; a text with at most ``limit`` opening brackets is not scanned at all."""
    if text.count("[") + text.count("{") <= limit:
        return None
    depth = 0
    for found in _JSON_TOKEN.finditer(text):
        char = text[found.start()]
        if char == "[" or char == "{":
            depth += 1
            if depth > limit:
                return _place(text, found.start())
        elif char == "]" or char == "}":
            depth -= 1
    return None


_TOML_TOKEN = re.compile(r'''
      "{3}(?:[^"\\]|\\[\s\S]|"(?!""))*"{3,5}     # multi-line basic string
    | '{3}[\s\S]*?'{3,5}                         # multi-line literal string
    | "(?:[^"\\\n]|\\.)*"                        # basic string
    | '[^'\n]*'                                  # literal string
    | \#[^\n]*                                   # comment
    | [\[\]{}.,=\n]
''', re.VERBOSE)

_SHOWN = 40
"""Longest table or key name a message shows whole."""


def _short(name: str) -> str:
    name = " ".join(name.split())
    return name if len(name) <= _SHOWN else name[:_SHOWN] + "…"


def toml_too_deep(text: str, limit: int = MAX_DEPTH) -> Deep | None:
    """The place where ``text`` (TOML) first nests more than ``limit`` levels, or None.

    A level is a table of a ``[header]`` (each dotted part; ``[[array]]`` one more), a part
    of a dotted key, an array or an inline table. Strings and comments are skipped. Linear
    in the text; a text with at most ``limit`` brackets and dots is not scanned at all."""
    if text.count("[") + text.count("{") + text.count(".") <= limit:
        return None
    table = 0            # levels of the current [header]
    table_name = ""
    depth = 0            # levels open where the scan is
    open_: list[tuple[str, int]] = []   # brackets open in a value, and the key levels of each
    extra = 0            # key levels of the value being read (innermost container)
    in_key = True        # reading a key: at a line's start, after '{' or ',' in a table
    dots = 0             # dots of the key being read
    header = -1          # dots of a [header] being read; -1: none
    array_header = swallow = False
    line_start = True
    statement = 0        # where the current line's key begins
    key_name = ""
    for found in _TOML_TOKEN.finditer(text):
        at = found.start()
        char = text[at]
        if char == "\n":
            if not open_:
                depth, extra, in_key, dots, line_start = table, 0, True, 0, True
                statement, key_name = at + 1, ""
            continue
        if char == "#":
            continue
        first = line_start
        line_start = False
        if header >= 0:                     # inside [a.b.c] or [[a.b.c]]
            if char == "[" and first is False and header == 0 and not array_header \
                    and text[at - 1] == "[":
                array_header = True
            elif char == ".":
                header += 1
                if header + 1 + array_header > limit:
                    return _place(text, at, _short(text[statement:at].lstrip("[ \t")))
            elif char == "]":
                table = header + 1 + array_header
                table_name = _short(text[statement:at].strip("[] \t"))
                depth, header, swallow = table, -1, array_header
            continue
        if char == "[" and first and not open_:
            header, array_header = 0, False
            continue
        if char == "]" and swallow:
            swallow = False
            continue
        if char == "[" or char == "{":
            depth += 1
            if depth > limit:
                return _place(text, at, _name(table_name, key_name))
            open_.append((char, extra))
            extra, dots, in_key = 0, 0, char == "{"
        elif char == "]" or char == "}":
            if open_:
                depth -= extra
                _, extra = open_.pop()
                depth -= 1
                in_key = False
        elif char == ".":
            if in_key:
                dots += 1
                if depth + dots > limit:
                    return _place(text, at, _name(table_name, _short(text[statement:at])))
        elif char == "=":
            if in_key:
                if not open_:
                    key_name = _short(text[statement:at].strip())
                extra, depth, dots, in_key = dots, depth + dots, 0, False
        elif char == "," and open_ and open_[-1][0] == "{":
            depth -= extra
            extra, dots, in_key = 0, 0, True
    return None


def _name(table: str, key: str) -> str:
    return ".".join(part for part in (table, key) if part) or "(top level)"
