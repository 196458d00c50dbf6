"""The G-code reader: RS-274 text in, SI motion items out.

``parse(text)`` reads a whole program into a ``Program``; ``read_file(path)`` streams the
items of a file of any length in constant memory. Both stop at the first error with a
``twin.errors.GCodeError`` carrying ``.line``, ``.column``, ``.code`` and the source line::

    line 12, col 5: two motion words in one block (G0, G1)

What is read
------------
The language of LinuxCNC 2.9's RS-274/NGC interpreter, for a machine with X and Y:

* G0, G1, G2/G3 (centre by I/J, relative to the start in G91.1, absolute in G90.1; or by
  R: R > 0 the arc of at most 180°, R < 0 the longer one; ``P`` = number of turns), G4
  (dwell, P in seconds), G10 L2/L20 (work offsets), G17 (G18/G19 are accepted as modes, but
  a motion in them is an error), G20/G21, G28/G28.1/G30/G30.1, G40, G43/G49 (along Z: no
  effect here), G53, G54–G59.3, G61/G61.1/G64 P Q (path control, a ``PathControl`` item),
  G80, G90/G91, G90.1/G91.1, G92/G92.1/G92.2/G92.3, G94 (G93 and G95 are refused), G98/G99;
  F, N, S, T; M0/M1/M60 (``pause`` events: the twin runs on), M2/M30, M3/M4/M5, M6,
  M7/M8/M9, M48/M49.
* G5/G5.1 splines, run as chords within 1 µm (``splines``).
* Parameters (``#1``, ``#<name>``, ``#<_global>``), expressions and functions, and O-word
  control flow with subroutines (``expr``, ``flow``).
* Z: ``ReaderOptions.z`` decides: refused (default), ignored, or the tool (pen, laser).
* Canned cycles (G73, G81–G89) with Z ignored or the tool: their moves between the holes.
* What LinuxCNC has and an XY table cannot run is refused naming the feature: probing,
  cutter compensation, lathe modes and cycles, spindle synchronisation, NURBS, modal-state
  save, other axes.

Decisions
---------
* Power-on state: G17 G21 G54 G64 G90 G91.1 G94 M5 M9, no motion mode (so ``X10`` on the
  first line is an error, not a silent rapid), no feed (a G1 before any F is an error).
* Order of execution inside a block as LinuxCNC's (``ORDER``): F before G20/G21 (``G20
  F10`` in G21 is 10 mm/min), S, T, M6, M3/M4/M5, M7/M8/M9, G4, modes, G10/G28/G30/G92,
  motion, M0/M1, M2/M30. G20/G21 and G90/G91 apply to the axis words of their own block.
* G4 blocks take no X/Y: ``G4 X2`` is a two-second dwell on some controls and a move on
  others, so it is refused rather than guessed.
* An end point within 1 nm of the start (``interpreter.COINCIDENT``) is the start: such a
  G0/G1 produces no ``Move``, such a G2/G3 is a full circle. Every arc ``Move`` is an exact
  circle through its start and end (see ``arcs`` for the tolerance, LinuxCNC's, and what is
  run when an end point is off its circle).
* Coordinates stay within ±1 km (``interpreter.WORKSPACE``); the machine's own travel
  limits are the planner's business.
* ``%`` on the first block line opens a tape; the next ``%`` ends the program. M2/M30 end
  it too. Text after the end is not read (RS-274/NGC), so it is neither run nor checked.
* Syntax: see ``twin.controller.gcode.lexer`` and ``twin.controller.gcode.expr``.

Error codes (``GCodeError.code``)
---------------------------------
``syntax``, ``bad-number``, ``unterminated-comment``, ``nested-comment``, ``unknown-word``,
``unknown-gcode``, ``unknown-mcode``, ``unsupported``, ``no-axis``, ``plane``,
``modal-conflict``, ``repeated-word``, ``unused-word``, ``ambiguous-word``, ``missing-word``,
``bad-value``, ``out-of-range``, ``no-motion-mode``, ``missing-feed``, ``zero-feed``,
``arc-missing-center``, ``arc-center-and-radius``, ``arc-zero-radius``,
``arc-end-off-circle``, ``arc-radius-too-small``, ``arc-full-circle-r``,
``unset-parameter``, ``unclosed-block``, ``unmatched-block``, ``bad-block``,
``unknown-sub``, ``loop-limit``, ``call-depth``, ``nesting``.
"""

from __future__ import annotations

import codecs
import io
import os
import threading
from collections.abc import Iterable, Iterator

from twin.controller.gcode.arcs import ArcTolerance, arc_sweep
from twin.controller.gcode.flow import Limits, Runner
from twin.controller.gcode.interpreter import FAST_LINE, ORDER, Interpreter, ReaderOptions
from twin.controller.gcode.items import (
    EVENT_KINDS,
    MOVE_KINDS,
    Dwell,
    Event,
    Item,
    Move,
    PathControl,
    Program,
    ProgramEnd,
)
from twin.controller.gcode.merge import merge_lines
from twin.controller.gcode.modal import ModalState
from twin.errors import byte_place

__all__ = [
    "EVENT_KINDS",
    "MOVE_KINDS",
    "ORDER",
    "ArcTolerance",
    "Dwell",
    "Event",
    "Interpreter",
    "Item",
    "Limits",
    "ModalState",
    "Move",
    "PathControl",
    "Program",
    "ProgramEnd",
    "ReaderOptions",
    "arc_sweep",
    "decode_program",
    "iter_items",
    "parse",
    "read_file",
]


def iter_items(lines: Iterable[str], *, start: tuple[float, float] = (0.0, 0.0),
               arc_tolerance: ArcTolerance | None = None,
               options: ReaderOptions | None = None,
               folder: str | None = None, fast: bool = True) -> Iterator[Item]:
    """Items of a program given as lines, one block at a time.

    Parameters
    ----------
    lines : iterable of str
        The program's lines, with or without their line breaks.
    start : tuple of float
        Position before the first block (m).
    arc_tolerance : ArcTolerance, optional
        Arc end-point tolerance; LinuxCNC's (``ArcTolerance.linuxcnc``) if None.
    options : ReaderOptions, optional
        Z handling, loop bounds, subroutine search path.
    folder : str, optional
        The program's folder: searched first for a called ``name.ngc``.
    fast : bool
        Run the commonest CAM lines by the reader's fast path (``Interpreter.fast_line``),
        and lines with parameters and expressions by their compiled shapes;
        False: every line the general way, the reference the tests compare it with. The
        items are the same.

    Yields
    ------
    Move, Dwell, Event, PathControl or ProgramEnd
        In execution order; the last is the ``ProgramEnd`` if the program has one.

    Raises
    ------
    GCodeError
        At the first bad block.
    """
    interpreter = Interpreter(start=start, arc_tolerance=arc_tolerance, options=options)
    runner = Runner(interpreter.execute_words, interpreter.parameters,
                    interpreter.options.limits, folder,
                    (FAST_LINE.fullmatch, interpreter.fast_line, interpreter.fast_move)
                    if fast else None)

    def started() -> bool:
        return interpreter.blocks > 0

    for item in merge_lines(runner.run(lines, started)):
        yield item
        if type(item) is ProgramEnd:
            return


def parse(text: str, *, start: tuple[float, float] = (0.0, 0.0),
          arc_tolerance: ArcTolerance | None = None, options: ReaderOptions | None = None,
          folder: str | None = None) -> Program:
    """Read a whole program.

    Parameters
    ----------
    text : str
        The program. Line breaks may be ``\\n``, ``\\r\\n`` or ``\\r``.
    start : tuple of float
        Position before the first block (m).
    arc_tolerance : ArcTolerance, optional
        Arc end-point tolerance; LinuxCNC's if None.
    options : ReaderOptions, optional
        Z handling, loop bounds, subroutine search path.
    folder : str, optional
        Searched first for a called ``name.ngc``.

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
    return Program(tuple(iter_items(lines, start=start, arc_tolerance=arc_tolerance,
                                    options=options, folder=folder)), text)


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
              options: ReaderOptions | None = None,
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
        Arc end-point tolerance; LinuxCNC's if None.
    options : ReaderOptions, optional
        Z handling, loop bounds, subroutine search path (the file's folder comes first).
    encoding : str
        Text encoding of the file.

    Yields
    ------
    Move, Dwell, Event or ProgramEnd
        In execution order.
    """
    with open(path, encoding=encoding, errors="replace", newline=None) as lines:
        yield from iter_items(lines, start=start, arc_tolerance=arc_tolerance,
                              options=options, folder=os.path.dirname(os.fspath(path)) or ".")
