"""Split one line of G-code into words: letter, value, column.

Syntax decisions (RS-274/NGC §3.3):

* Case does not matter: ``g1 x10`` is ``G1 X10``.
* Spaces and tabs are allowed anywhere outside comments, also inside a word: ``G 1``,
  ``X - 1 . 5`` and even ``X1 0`` (= ``X10``) read as the standard says.
* A number is an optional sign, digits and at most one decimal point (``1``, ``1.``, ``.5``,
  ``-0.5``); no exponents. Its magnitude must stay below ``MAX_VALUE``.
* ``( ... )`` is a comment (no nesting); ``;`` comments out the rest of the line.
* A leading ``/`` (block delete) is accepted and ignored: the block-delete switch is off.

Lexing is linear in the line's length, blank runs and comments included.

Columns are 1-based positions in the original line, so an error points at the word's letter.
"""

from __future__ import annotations

import re

from twin.errors import GCodeError

__all__ = ["MAX_VALUE", "Word", "clean", "lex", "words"]

MAX_VALUE = 1e9
"""Largest magnitude of any number in a program (program units)."""

Word = tuple[str, float, int]
"""A word: upper-case letter, value, 1-based column of the letter."""

# Whitespace may sit between any two characters of a word, so a naive pattern can split a
# run of blanks in many ways and backtrack exponentially on a bad line. Here every blank run
# is followed by a specific character (digit, point, letter) and every repetition is
# possessive (*+, ?+), so matching is linear in the line length.
_BLANKS = r"[ \t]*+"
_NUMBER = (rf"[+-]?{_BLANKS}(?:[0-9](?:{_BLANKS}[0-9])*+(?:{_BLANKS}\.(?:{_BLANKS}[0-9])*+)?+"
           rf"|\.(?:{_BLANKS}[0-9])++)")
_WORD = re.compile(rf"{_BLANKS}([A-Z]){_BLANKS}({_NUMBER})")
_WORDS = re.compile(rf"(?:{_BLANKS}[A-Z]{_BLANKS}{_NUMBER})*+{_BLANKS}")
# The words of a line _WORDS has accepted, found by their letters (a number holds none). A
# pattern that starts with the blanks would be tried at every position of a blank run, each
# try crossing the rest of the run: quadratic in its length (a 64 KiB comment, blanked,
# took 3 s).
_LETTER_WORD = re.compile(rf"([A-Z]){_BLANKS}({_NUMBER})")
_SPECIAL = re.compile(r"[();]")


def _error(line: int, column: int, message: str, code: str, source: str) -> GCodeError:
    return GCodeError(line, column, message, code=code, source=source)


def _blank_comments(text: str, line: int) -> str:
    """``text`` with every comment replaced by spaces (columns stay where they were)."""
    parts: list[str] = []
    done = 0
    for match in _SPECIAL.finditer(text):
        at = match.start()
        if at < done:  # inside a comment already blanked
            continue
        char = text[at]
        if char == ";":
            parts += [text[done:at], " " * (len(text) - at)]
            return "".join(parts)
        if char == ")":
            raise _error(line, at + 1, "')' without an opening '('", "syntax", text)
        close = text.find(")", at + 1)
        if close < 0:
            raise _error(line, at + 1, "comment '(' is not closed on this line",
                         "unterminated-comment", text)
        nested = text.find("(", at + 1, close)
        if nested >= 0:
            raise _error(line, nested + 1, "'(' inside a comment: comments do not nest",
                         "nested-comment", text)
        parts += [text[done:at], " " * (close + 1 - at)]
        done = close + 1
    parts.append(text[done:])
    return "".join(parts)


def _diagnose(code: str, line: int, source: str) -> GCodeError:
    """The error for a line that is not a sequence of words: at the first text that is not."""
    pos = 0
    while (found := _WORD.match(code, pos)) is not None:
        pos = found.end()
    while code[pos] in " \t":
        pos += 1
    char = code[pos]
    if "A" <= char <= "Z":
        return _error(line, pos + 1, f"{char} word without a valid number", "bad-number",
                      source)
    if char in "+-.0123456789":
        return _error(line, pos + 1, "number without a letter before it", "syntax", source)
    return _error(line, pos + 1, f"unexpected character {char!r}", "syntax", source)


def clean(text: str, line: int = 1) -> str:
    """A line ready to read: comments blanked, upper case, block delete removed; columns
    stay where they were.

    Raises
    ------
    GCodeError
        ``syntax`` (a character outside ASCII, a stray ')'), ``unterminated-comment``,
        ``nested-comment``.
    """
    code = _blank_comments(text, line) if _SPECIAL.search(text) else text
    if not code.isascii():
        at = next(i for i, char in enumerate(code) if not char.isascii())
        raise _error(line, at + 1, f"unexpected character {code[at]!r}", "syntax", text)
    code = code.upper()
    if "/" in code and code.lstrip(" \t").startswith("/"):
        code = code.replace("/", " ", 1)
    return code


def words(code: str, line: int, source: str) -> list[Word]:
    """Words of a line ``clean`` has prepared (plain words only: no parameters,
    expressions or O-words, see ``twin.controller.gcode.expr``)."""
    if _WORDS.fullmatch(code) is None:
        raise _diagnose(code, line, source)
    found_words: list[Word] = []
    for found in _LETTER_WORD.finditer(code):
        letter, number = found.group(1, 2)
        if " " in number or "\t" in number:
            number = number.replace(" ", "").replace("\t", "")
        value = float(number)
        if not -MAX_VALUE < value < MAX_VALUE:
            shown = number if len(number) <= 24 else f"{number[:12]}… ({len(number)} characters)"
            raise _error(line, found.start(1) + 1, f"{letter} value {shown} is out of range "
                                                   f"(|value| < {MAX_VALUE:g})", "bad-number",
                         source)
        found_words.append((letter, value, found.start(1) + 1))
    return found_words


def lex(text: str, line: int = 1) -> list[Word]:
    """Words of one line, in order.

    Parameters
    ----------
    text : str
        The line, without its line break.
    line : int
        1-based line number, for errors.

    Returns
    -------
    list of (str, float, int)
        ``(letter, value, column)`` per word; empty for a blank or comment-only line.

    Raises
    ------
    GCodeError
        ``syntax``, ``bad-number``, ``unterminated-comment``, ``nested-comment``.
    """
    return words(clean(text, line), line, text)
