"""The G-code reader: RS-274 text in, SI motion items out.

``parse(text)`` reads a whole program into a ``Program``; ``read_file(path)`` streams the
items of a file of any length in constant memory. Both stop at the first error with a
``twin.errors.GCodeError`` carrying ``.line``, ``.column``, ``.code`` and the source line::

    line 12, col 5: two motion words in one block (G0, G1)

What is read
------------
G0, G1, G2/G3 (centre by I/J relative to the start, or by R: R > 0 the arc of at most 180°,
R < 0 the longer one; ``P`` = number of turns), G4 (dwell, P in seconds), G17 (G18/G19 are
accepted as modes, but a motion in them is an error), G20/G21, G90/G91, G94 (power-on; G93
and G95 are refused), G80 (cancel motion mode), G40/G49/G54 (the states this machine is
always in, accepted for CAM headers), F, N, M2/M30, and M3/M4/M5, M6, M7/M8/M9, S and T as
``Event`` items. Z, K and other axes are errors: this machine has only X and Y.

Decisions
---------
* Power-on state: G17 G21 G90 G94 M5 M9, no motion mode (so ``X10`` on the first line is
  an error, not a silent rapid), no feed (a G1 before any F is an error).
* Order of execution inside a block as RS-274/NGC: F, S, T, M6, M3/M4/M5, M7/M8/M9, G4,
  then motion, then M2/M30. G20/G21 and G90/G91 apply to the words of their own block.
* G4 blocks take no X/Y: ``G4 X2`` is a two-second dwell on some controls and a move on
  others, so it is refused rather than guessed.
* An end point within 1 nm of the start (``interpreter.COINCIDENT``) is the start: such a
  G0/G1 produces no ``Move``, such a G2/G3 is a full circle. Every arc ``Move`` is an exact
  circle through its start and end (I/J centres are corrected, see ``arcs``).
* Coordinates stay within ±1 km (``interpreter.WORKSPACE``); the machine's own travel
  limits are the planner's business.
* ``%`` on the first block line opens a tape; the next ``%`` ends the program. M2/M30 end
  it too. Text after the end is not read (RS-274/NGC), so it is neither run nor checked.
* Syntax: see ``twin.controller.gcode.lexer``; arc tolerance: ``twin.controller.gcode.arcs``.

Error codes (``GCodeError.code``)
---------------------------------
``syntax``, ``bad-number``, ``unterminated-comment``, ``nested-comment``, ``unknown-word``,
``unknown-gcode``, ``unknown-mcode``, ``unsupported``, ``no-axis``, ``plane``,
``modal-conflict``, ``repeated-word``, ``unused-word``, ``ambiguous-word``, ``missing-word``,
``bad-value``, ``out-of-range``, ``no-motion-mode``, ``missing-feed``, ``zero-feed``,
``arc-missing-center``, ``arc-center-and-radius``, ``arc-zero-radius``,
``arc-end-off-circle``, ``arc-radius-too-small``, ``arc-full-circle-r``.
"""

from __future__ import annotations

import codecs
import io
import os
import threading
from collections.abc import Iterable, Iterator

from twin.controller.gcode.arcs import ArcTolerance, arc_sweep
from twin.controller.gcode.interpreter import Interpreter
from twin.controller.gcode.items import (
    EVENT_KINDS,
    MOVE_KINDS,
    Dwell,
    Event,
    Item,
    Move,
    Program,
    ProgramEnd,
)
from twin.controller.gcode.modal import ModalState
from twin.errors import byte_place

__all__ = [
    "EVENT_KINDS",
    "MOVE_KINDS",
    "ArcTolerance",
    "Dwell",
    "Event",
    "Interpreter",
    "Item",
    "ModalState",
    "Move",
    "Program",
    "ProgramEnd",
    "arc_sweep",
    "decode_program",
    "iter_items",
    "parse",
    "read_file",
]


def iter_items(lines: Iterable[str], *, start: tuple[float, float] = (0.0, 0.0),
               arc_tolerance: ArcTolerance | None = None) -> Iterator[Item]:
    """Items of a program given as lines, one block at a time.

    Parameters
    ----------
    lines : iterable of str
        The program's lines, with or without their line breaks.
    start : tuple of float
        Position before the first block (m).
    arc_tolerance : ArcTolerance, optional
        Arc end-point tolerance; the defaults of ``ArcTolerance`` if None.

    Yields
    ------
    Move, Dwell, Event or ProgramEnd
        In execution order; the last is the ``ProgramEnd`` if the program has one.

    Raises
    ------
    GCodeError
        At the first bad block.
    """
    interpreter = Interpreter(start=start, arc_tolerance=arc_tolerance)
    tape_opened = False
    for number, raw in enumerate(lines, start=1):
        text = raw.rstrip("\r\n")
        if text.lstrip(" \t").startswith("%"):
            if interpreter.blocks == 0 and not tape_opened:
                tape_opened = True
                continue
            return
        yield from interpreter.execute(text, line=number)
        if interpreter.ended:
            return


def parse(text: str, *, start: tuple[float, float] = (0.0, 0.0),
          arc_tolerance: ArcTolerance | None = None) -> Program:
    """Read a whole program.

    Parameters
    ----------
    text : str
        The program. Line breaks may be ``\\n``, ``\\r\\n`` or ``\\r``.
    start : tuple of float
        Position before the first block (m).
    arc_tolerance : ArcTolerance, optional
        Arc end-point tolerance; the defaults of ``ArcTolerance`` if None.

    Returns
    -------
    Program
        Its items and ``text``.

    Raises
    ------
    GCodeError
        At the first bad block, with line, column, code and source line.

    Examples
    --------
    >>> prog = parse("G21 G90 G1 X10 Y0 F600\\nG3 X0 Y10 I-10 J0\\nM2")
    >>> [move.kind for move in prog.moves]
    ['line', 'arc']
    >>> round(prog.moves[0].feed, 6)  # 600 mm/min (m/s)
    0.01
    """
    lines = io.StringIO(text, newline=None)
    return Program(tuple(iter_items(lines, start=start, arc_tolerance=arc_tolerance)), text)


def decode_program(data: bytes, encoding: str = "utf-8") -> tuple[str, list[str]]:
    """A program's text from its bytes, and a note for every run of bytes that are not valid
    in ``encoding``: those become U+FFFD (harmless in a comment, a ``syntax`` error with its
    place anywhere else), and each note says where they were::

        line 3, column 12 (byte 57): 1 byte not UTF-8 (0xe9), read as U+FFFD

    At most 20 notes (then how many more). One pass over the bytes, however many are bad."""
    _bad.places = places = []
    text = data.decode(encoding, errors=_NOTE_BAD_BYTES)
    notes = []
    for start, end in places[:20]:
        line, column = byte_place(data, start)
        n = end - start
        notes.append(f"line {line}, column {column} (byte {start}): {n} byte"
                     f"{'s' if n > 1 else ''} not {encoding.upper()} "
                     f"({data[start:end].hex(' ', 1) if n > 1 else hex(data[start])}), "
                     "read as U+FFFD")
    if len(places) > len(notes):
        notes.append(f"… and {len(places) - len(notes)} more such places")
    return text, notes


_NOTE_BAD_BYTES = "twin.gcode.note-bad-bytes"
_bad = threading.local()


def _note_bad_bytes(exc: UnicodeError) -> tuple[str, int]:
    """The ``replace`` error handler that also notes where (``decode_program``)."""
    if not isinstance(exc, UnicodeDecodeError):
        raise exc
    _bad.places.append((exc.start, exc.end))
    return "\ufffd", exc.end


codecs.register_error(_NOTE_BAD_BYTES, _note_bad_bytes)


def read_file(path: str | os.PathLike[str], *, start: tuple[float, float] = (0.0, 0.0),
              arc_tolerance: ArcTolerance | None = None,
              encoding: str = "utf-8") -> Iterator[Item]:
    """Stream the items of a program file in constant memory; the same items as ``parse``.

    The file is opened on the first ``next()`` and closed when the generator finishes or is
    closed. Bytes that are not valid in ``encoding`` become U+FFFD: harmless in a comment,
    a ``syntax`` error with its place anywhere else.

    Parameters
    ----------
    path : str or PathLike
        The program file.
    start : tuple of float
        Position before the first block (m).
    arc_tolerance : ArcTolerance, optional
        Arc end-point tolerance; the defaults of ``ArcTolerance`` if None.
    encoding : str
        Text encoding of the file.

    Yields
    ------
    Move, Dwell, Event or ProgramEnd
        In execution order.
    """
    with open(path, encoding=encoding, errors="replace", newline=None) as lines:
        yield from iter_items(lines, start=start, arc_tolerance=arc_tolerance)
