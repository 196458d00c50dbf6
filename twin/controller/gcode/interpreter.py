"""Run G-code blocks against the modal state, one block at a time, all or nothing.

Each block goes through the steps of grbl's ``gc_execute_line``:

1. read the words (``lex``) and sort them: G/M codes into their modal groups (two of one
   group is an error), value words into a table (a repeated letter is an error);
2. work out, from a copy of the modal state, what the block means, in the RS-274/NGC order
   of execution: units, modes, F, S, T, M6, M3/M4/M5, M7/M8/M9, G4, motion, M2/M30; check
   every word on the way (a word that nothing in the block uses is an error too);
3. commit the new modal state and position only when nothing failed.

A bad block therefore changes nothing: the ``Interpreter`` is exactly as it was before it.
Units are converted to SI here: lengths by 1 mm or 1 inch, F by unit/min, S by rev/min.
"""

from __future__ import annotations

import math
from dataclasses import replace

from twin.controller.gcode.arcs import (
    ArcError,
    ArcTolerance,
    center_from_offset,
    center_from_radius,
)
from twin.controller.gcode.items import Dwell, Event, Item, Move, ProgramEnd
from twin.controller.gcode.lexer import Word, lex
from twin.controller.gcode.modal import CODES, GROUP_NAMES, Code, ModalState, code_name
from twin.errors import ConfigError, GCodeError
from twin.units import INCH, MM, RPM

__all__ = ["COINCIDENT", "WORKSPACE", "Interpreter"]

COINCIDENT = 1e-9
"""End points within 1 nm of the start are the start (m), far below the 0.2 µm encoder
resolution: ``G20 G2 X1 I…`` after ``G21 X25.4`` is a full circle although 1·25.4e-3 and
25.4·1e-3 differ in the last bit, and no arc is left whose sweep rounding could not tell
from a full turn. G0/G1 moves shorter than this produce no ``Move``."""

WORKSPACE = 1e3
"""Largest coordinate a program may reach (m); keeps every computation far from overflow."""

_VALUE_LETTERS = frozenset("FIJNPRSTXY")
_OTHER_AXES = frozenset("ABCUVW")
_WRITTEN = {"rapid": "G0", "line": "G1", "arc_cw": "G2", "arc_ccw": "G3"}
_SPINDLE = {"cw": "spindle_cw", "ccw": "spindle_ccw", "stop": "spindle_stop"}
_COOLANT = {"mist": "coolant_mist", "flood": "coolant_flood", "off": "coolant_off"}


def _whole(value: float) -> bool:
    return value == math.floor(value)


class _Block:
    """The words of one block sorted by role, and its place for errors."""

    __slots__ = ("codes", "line", "source", "values")

    def __init__(self, line: int, source: str):
        self.line = line
        self.source = source
        self.codes: dict[str, tuple[Code, tuple[str, float], int]] = {}
        """Modal group → (table row, (letter, value) as written, column)."""
        self.values: dict[str, tuple[float, int]] = {}     # letter → (value, column)

    def error(self, column: int, message: str, code: str) -> GCodeError:
        return GCodeError(self.line, column, message, code=code, source=self.source)

    def column(self, *letters: str) -> int:
        """Column of the first present word among ``letters`` (in line order), else 1."""
        columns = [self.values[letter][1] for letter in letters if letter in self.values]
        return min(columns, default=1)


def _read(words: list[Word], line: int, source: str) -> _Block:
    """Step 1: sort the words, refusing unknown, unsupported, conflicting, repeated ones."""
    block = _Block(line, source)
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
        elif letter in _VALUE_LETTERS:
            if letter in block.values:
                raise block.error(column, f"repeated {letter} word in one block",
                                  "repeated-word")
            block.values[letter] = (value, column)
        elif letter == "Z":
            raise block.error(column, "no Z axis on this machine", "no-axis")
        elif letter == "K":
            raise block.error(column, "K word (arc centre along Z): no Z axis on this machine",
                              "no-axis")
        elif letter in _OTHER_AXES:
            raise block.error(column, f"no {letter} axis on this machine", "no-axis")
        else:
            raise block.error(column, f"unknown word {letter}", "unknown-word")
    return block


def _at_least_zero(block: _Block, letter: str, what: str) -> float:
    value, column = block.values[letter]
    if value < 0:
        raise block.error(column, f"{what} must be >= 0", "bad-value")
    return value


def _whole_number(block: _Block, letter: str, what: str, *, least: int = 0) -> int:
    value, column = block.values[letter]
    if value < least or not _whole(value):
        raise block.error(column, f"{what} must be a whole number >= {least}", "bad-value")
    return int(value)


def _machine_functions(block: _Block, old: ModalState, changes: dict[str, object]) -> list[Item]:
    """Events of S, T, M6, M3/M4/M5, M7/M8/M9 in that order; records them in ``changes``."""
    codes, values, line = block.codes, block.values, block.line
    items: list[Item] = []
    if "S" in values:
        speed = _at_least_zero(block, "S", "spindle speed S") * RPM
        changes["spindle_speed"] = speed
        items.append(Event("spindle_speed", speed, line))
    if "T" in values:
        tool = _whole_number(block, "T", "tool number T")
        changes["tool"] = tool
        items.append(Event("tool_select", tool, line))
    if "tool_change" in codes:
        items.append(Event("tool_change", changes.get("tool", old.tool), line))
    for group, kinds in (("spindle", _SPINDLE), ("coolant", _COOLANT)):
        if group in codes:
            changes[group] = codes[group][0].value
            items.append(Event(kinds[codes[group][0].value], None, line))
    return items


def _check_claims(block: _Block, *, dwell: bool, arc: bool) -> None:
    """Every I, J, R, P word must be used by exactly one command of the block."""
    values = block.values
    for letter in "IJR":
        if letter in values and not arc:
            raise block.error(values[letter][1], f"{letter} word without an arc (G2/G3) to "
                                                 "use it", "unused-word")
    if "P" in values:
        if dwell and arc:
            raise block.error(values["P"][1], "P word claimed by both G4 (dwell) and the arc "
                                              "(turns): put them in two blocks",
                              "ambiguous-word")
        if not (dwell or arc):
            raise block.error(values["P"][1], "P word without G4 or an arc to use it",
                              "unused-word")


class Interpreter:
    """The modal state and position of a running program; ``execute`` runs one block.

    Parameters
    ----------
    start : tuple of float
        Position before the first block, absolute machine coordinates (m).
    arc_tolerance : ArcTolerance, optional
        How far an arc end point may be off its circle (see ``twin.controller.gcode.arcs``).

    Examples
    --------
    >>> interp = Interpreter()
    >>> interp.execute("G1 X10 F600", line=1)[0].end
    (0.01, 0.0)
    >>> interp.state.feed  # 600 mm/min
    0.01
    """

    def __init__(self, *, start: tuple[float, float] = (0.0, 0.0),
                 arc_tolerance: ArcTolerance | None = None):
        try:
            x, y = (float(value) for value in start)
        except (TypeError, ValueError) as exc:
            raise ConfigError("start", f"must be a pair of numbers (m), got {start!r}") from exc
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ConfigError("start", f"must be finite, got {start!r}")
        self._position = (x, y)
        self._modal = ModalState()
        self._tolerance = ArcTolerance() if arc_tolerance is None else arc_tolerance
        self.blocks = 0
        """Blocks run so far (lines with at least one word)."""
        self.ended = False
        """True once an M2/M30 has run."""

    @property
    def state(self) -> ModalState:
        """The modal state in force (immutable snapshot)."""
        return self._modal

    @property
    def position(self) -> tuple[float, float]:
        """The programmed position after the last block (m)."""
        return self._position

    def execute(self, text: str, *, line: int = 1) -> tuple[Item, ...]:
        """Run one block; on error raise ``GCodeError`` and change nothing.

        Parameters
        ----------
        text : str
            One line of G-code, without its line break.
        line : int
            Its 1-based line number, stamped on items and errors.

        Returns
        -------
        tuple
            The ``Event``, ``Dwell``, ``Move`` and ``ProgramEnd`` items of the block, in
            execution order; empty for a block that only changes modes.
        """
        words = lex(text, line)
        if not words:
            return ()
        block = _read(words, line, text)
        modal, position, items = self._run(block)
        self._modal, self._position = modal, position
        self.blocks += 1
        self.ended = self.ended or "stopping" in block.codes
        return tuple(items)

    def _run(self, block: _Block) -> tuple[ModalState, tuple[float, float], list[Item]]:
        """Step 2: what the block means, from a copy of the state; raises, never mutates."""
        old, codes, values = self._modal, block.codes, block.values
        changes: dict[str, object] = {
            group: codes[group][0].value
            for group in ("motion", "plane", "distance", "units", "feed_mode") if group in codes
        }
        unit = INCH if changes.get("units", old.units) == "inch" else MM
        number = None
        if "N" in values:
            number = _whole_number(block, "N", "block number N")
        if "F" in values:
            changes["feed"] = _at_least_zero(block, "F", "feed F") * unit / 60.0
        items = _machine_functions(block, old, changes)
        dwell = "non_modal" in codes
        if dwell:
            if "X" in values or "Y" in values:
                letter = "X" if "X" in values else "Y"
                raise block.error(values[letter][1], f"{letter} word in a G4 block: dwell "
                                  "time is P (s), and a move beside a dwell is not run here",
                                  "ambiguous-word")
            if "P" not in values:
                raise block.error(codes["non_modal"][2], "G4 needs a P word (dwell time, s)",
                                  "missing-word")
            items.append(Dwell(_at_least_zero(block, "P", "dwell time P (s)"), block.line))
        changes = {name: value for name, value in changes.items() if getattr(old, name) != value}
        modal = replace(old, **changes) if changes else old
        arc = modal.motion == "arc_cw" or modal.motion == "arc_ccw"
        moves = "X" in values or "Y" in values or (arc and not values.keys().isdisjoint("IJR"))
        _check_claims(block, dwell=dwell, arc=moves and arc)
        position = self._position
        if moves:
            position, move = self._motion(block, modal, unit, number)
            if move is not None:
                items.append(move)
        if "stopping" in codes:
            items.append(ProgramEnd(codes["stopping"][0].value, block.line))
        return modal, position, items

    def _motion(self, block: _Block, modal: ModalState, unit: float,
                number: int | None) -> tuple[tuple[float, float], Move | None]:
        """The move a block with axis (or arc centre) words commands, and the new position."""
        values = block.values
        written_motion = block.codes.get("motion")
        column = (written_motion[2] if written_motion is not None
                  else block.column("X", "Y", "I", "J", "R"))
        motion = modal.motion
        if motion is None:
            raise block.error(block.column("X", "Y"), "X/Y words without a motion mode in "
                              "force: program G0, G1, G2 or G3", "no-motion-mode")
        name = _WRITTEN[motion]
        if modal.plane != "xy":
            plane = {"xz": "G18", "yz": "G19"}[modal.plane]
            raise block.error(column, f"this machine has only the XY plane ({plane} is in "
                                      f"force): program G17", "plane")
        start = self._position
        end = [*start]
        for axis, letter in enumerate("XY"):
            if letter in values:
                offset = values[letter][0] * unit
                end[axis] = start[axis] + offset if modal.distance == "incremental" else offset
        if not (abs(end[0]) <= WORKSPACE and abs(end[1]) <= WORKSPACE):
            raise block.error(block.column("X", "Y"), f"end point ({end[0] / MM:.6g}, "
                              f"{end[1] / MM:.6g}) mm is beyond ±{WORKSPACE / MM:g} mm",
                              "out-of-range")
        if abs(end[0] - start[0]) <= COINCIDENT and abs(end[1] - start[1]) <= COINCIDENT:
            end = [*start]
        target = (end[0], end[1])
        feed = None if motion == "rapid" else modal.feed
        if motion != "rapid" and not feed:
            if feed is None:
                raise block.error(column, f"{name} needs a feed: no F word programmed yet",
                                  "missing-feed")
            raise block.error(values["F"][1] if "F" in values else column,
                              f"{name} with zero feed (F0)", "zero-feed")
        if motion == "rapid" or motion == "line":
            if target == start:
                return target, None
            return target, Move(motion, start, target, feed, line=block.line,
                                block_number=number)
        return target, self._arc(block, motion, start, target, feed, unit, number, column)

    def _arc(self, block: _Block, motion: str, start: tuple[float, float],
             target: tuple[float, float], feed: float, unit: float, number: int | None,
             column: int) -> Move:
        """The G2/G3 move from ``start`` to ``target``: turns, centre, tolerance checks."""
        values, name = block.values, _WRITTEN[motion]
        ccw = motion == "arc_ccw"
        turns = 0
        if "P" in values:
            turns = _whole_number(block, "P", "arc P (number of turns)", least=1) - 1
        has_offset = "I" in values or "J" in values
        if "R" in values and has_offset:
            raise block.error(values["R"][1], "arc with both I/J and R: program the centre "
                                              "one way only", "arc-center-and-radius")
        if not ("R" in values or has_offset):
            raise block.error(column, f"{name} needs the centre as I/J or the radius as R",
                              "arc-missing-center")
        try:
            if "R" in values:
                center = center_from_radius(start, target, values["R"][0] * unit, ccw=ccw,
                                            tolerance=self._tolerance)
            else:
                programmed = (start[0] + values["I"][0] * unit if "I" in values else start[0],
                              start[1] + values["J"][0] * unit if "J" in values else start[1])
                center = center_from_offset(start, target, programmed, ccw=ccw, turns=turns,
                                            tolerance=self._tolerance)
        except ArcError as exc:
            raise block.error(column, exc.message, exc.code) from None
        return Move("arc", start, target, feed, center, ccw, turns, block.line, number)
