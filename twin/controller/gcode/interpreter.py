"""Run G-code blocks against the modal state, one block at a time, all or nothing.

Each block goes through the steps of grbl's ``gc_execute_line``:

1. read the words (``lex``, or ``expr`` for the LinuxCNC language) and sort them: G/M codes
   into their modal groups (two of one group is an error), value words into a table (a
   repeated letter is an error);
2. work out, from a copy of the modal state, what the block means, in LinuxCNC's order of
   execution (``ORDER``); check every word on the way (a word that nothing in the block
   uses is an error too);
3. commit the new modal state, offsets and position only when nothing failed.

A bad block therefore changes nothing: the ``Interpreter`` is exactly as it was before it.
Units are converted to SI here: lengths by 1 mm or 1 inch, F by unit/min, S by rev/min.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field, replace

from twin.controller.gcode.arcs import (
    ArcError,
    ArcTolerance,
    center_from_offset,
    center_from_radius,
)
from twin.controller.gcode.flow import Limits, Parameters
from twin.controller.gcode.items import (
    Dwell,
    Event,
    Item,
    Move,
    PathControl,
    ProgramEnd,
    trusted_move,
)
from twin.controller.gcode.lexer import MAX_VALUE, Word, lex
from twin.controller.gcode.modal import CODES, GROUP_NAMES, Code, ModalState, code_name
from twin.controller.gcode.splines import SPLINE_TOLERANCE, bezier_chords
from twin.errors import ConfigError, GCodeError
from twin.units import INCH, MM, RPM

__all__ = ["COINCIDENT", "FAST_LINE", "ORDER", "WORKSPACE", "Interpreter", "ReaderOptions"]

_NUMBER = r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)"
FAST_LINE = re.compile(rf"(?:[Nn]([0-9]+) ?)?(?:[Gg]0?([01]) ?)?(?:[Xx]({_NUMBER}) ?)?"
                       rf"(?:[Yy]({_NUMBER}) ?)?(?:[Ff]([0-9]+\.?[0-9]*|\.[0-9]+))? *")
"""The commonest line of CAM output, ``[N…] [G0|G1] X… Y… [F…]``: ``Interpreter.fast_line``
runs it."""

COINCIDENT = 1e-9
"""End points within 1 nm of the start are the start (m), far below the 0.2 µm encoder
resolution: ``G20 G2 X1 I…`` after ``G21 X25.4`` is a full circle although 1·25.4e-3 and
25.4·1e-3 differ in the last bit, and no arc is left whose sweep rounding could not tell
from a full turn. G0/G1 moves shorter than this produce no ``Move``."""

WORKSPACE = 1e3
"""Largest coordinate a program may reach (m); keeps every computation far from overflow."""

ORDER = (
    ("parameters", "assignments (`#1 = …`) take effect after the line is read: `X#1` in "
                   "the same line uses the old value"),
    ("O-words", "a control statement is alone on its line"),
    ("F", "feed, in the units in force before this block's G20/G21"),
    ("S", "spindle speed"),
    ("T", "tool selection"),
    ("M6", "tool change (an event)"),
    ("M3, M4, M5", "spindle; with z = \"tool\", the tool on/off event"),
    ("M7, M8, M9", "coolant"),
    ("G4", "dwell"),
    ("G17, G18, G19", "plane"),
    ("G20, G21", "length units: the axis, I/J/R and P/Q words of this block are in them"),
    ("G40, G43, G49", "cutter and tool length compensation (only off, or along Z)"),
    ("G54–G59.3", "coordinate system"),
    ("G61, G61.1, G64", "path control"),
    ("G90, G91", "distance mode"),
    ("G90.1, G91.1", "arc centre distance mode"),
    ("G10, G28, G30, G92", "offsets and homing; they take the block's axis words"),
    ("G0–G3, G53", "motion; with z = \"tool\", a Z change switches the tool before the move"),
    ("M0, M1, M60", "pause (an event)"),
    ("M2, M30", "program end"),
)
"""Order of execution inside one block (LinuxCNC's ``execute_block``), as (words, note)."""

_VALUE_LETTERS = frozenset("DFHIJLNPQRSTXYZ@^")
_OTHER_AXES = frozenset("ABCUVW")
_WRITTEN = {"rapid": "G0", "line": "G1", "arc_cw": "G2", "arc_ccw": "G3", "cubic": "G5",
            "quadratic": "G5.1"}
_SPINDLE = {"cw": "spindle_cw", "ccw": "spindle_ccw", "stop": "spindle_stop"}
_COOLANT = {"mist": "coolant_mist", "flood": "coolant_flood", "off": "coolant_off"}
_Z_MODES = ("error", "ignore", "tool")
_AXIS_GROUP = ("set_offsets", "home_g28", "home_g30", "g92")
"""Non-modal codes that take the block's axis words instead of a motion."""


@dataclass(frozen=True, slots=True)
class ReaderOptions:
    """How the reader treats what this two-axis machine does not have.

    Attributes
    ----------
    z : str
        Z words: ``"error"`` (the default: a program for another machine is refused at
        its first Z), ``"ignore"`` (read and dropped) or ``"tool"`` (a pen or laser
        machine: the tool is on while Z is at or below ``tool_z`` and the spindle, once
        programmed, is on with S > 0; each change is a ``tool_on``/``tool_off`` event).
    tool_z : float
        Work Z at or below which the tool is on, with ``z = "tool"`` (m).
    arc_tolerance : ArcTolerance or None
        How far an arc's end may be off its circle; None: LinuxCNC's own, in the units of
        the block.
    limits : Limits
        Loop and call bounds and the subroutine search path.
    work_offsets : dict
        Coordinate system (1 = G54 … 9 = G59.3) → its zero in machine coordinates (x, y)
        (m), the machine's at the start; G10 L2/L20 change them for the program.
    """

    z: str = "error"
    tool_z: float = 0.0
    arc_tolerance: ArcTolerance | None = None
    limits: Limits = field(default_factory=Limits)
    work_offsets: dict[int, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for system, offset in self.work_offsets.items():
            if system not in range(1, 10) or len(offset) != 2 or not all(
                    math.isfinite(v) and abs(v) <= WORKSPACE for v in offset):
                raise ConfigError("gcode.work_offsets", f"system {system!r}: must be 1-9 with "
                                  f"a finite (x, y) (m), got {offset!r}")
        if self.z not in _Z_MODES:
            raise ConfigError("gcode.z", f"must be one of {_Z_MODES}, got {self.z!r}")
        if not (isinstance(self.tool_z, float | int) and math.isfinite(self.tool_z)
                and abs(self.tool_z) <= WORKSPACE):
            raise ConfigError("gcode.tool_z", f"must be a finite height (m), got "
                                              f"{self.tool_z!r}")


def _whole(value: float) -> bool:
    return value == math.floor(value)


class _Block:
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


_Z_HINT = ("set controller.gcode.z = \"ignore\" to drop Z, or \"tool\" to run Z (pen) "
           "and M3/M5 (laser) as the tool on and off")


def _read(words: list[Word], line: int, source: str, file: str | None, z_mode: str) -> _Block:
    """Step 1: sort the words, refusing unknown, unsupported, conflicting, repeated ones."""
    block = _Block(line, source, file)
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
            if letter == "Z" and z_mode == "error":
                raise block.error(column, f"no Z axis on this machine ({_Z_HINT})",
                                  "no-axis")
            block.values[letter] = (value, column)
        elif letter == "K":
            if z_mode == "error":
                raise block.error(column, "K word (arc centre along Z): no Z axis on this "
                                  f"machine ({_Z_HINT})", "no-axis")
            if letter in block.values:
                raise block.error(column, "repeated K word in one block", "repeated-word")
            block.values[letter] = (value, column)
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


def _whole_number(block: _Block, letter: str, what: str, *, least: int = 0,
                  most: int | None = None) -> int:
    value, column = block.values[letter]
    if value < least or not _whole(value) or (most is not None and value > most):
        span = f">= {least}" if most is None else f"from {least} to {most}"
        raise block.error(column, f"{what} must be a whole number {span}", "bad-value")
    return int(value)


class Interpreter:
    """The modal state, offsets and position of a running program; ``execute`` runs one
    block.

    Parameters
    ----------
    start : tuple of float
        Position before the first block, absolute machine coordinates (m).
    arc_tolerance : ArcTolerance, optional
        How far an arc end point may be off its circle (see ``twin.controller.gcode.arcs``);
        overrides ``options.arc_tolerance``.
    options : ReaderOptions, optional
        Z handling, arc tolerance, loop bounds.

    Examples
    --------
    >>> interp = Interpreter()
    >>> interp.execute("G1 X10 F600", line=1)[0].end
    (0.01, 0.0)
    >>> interp.state.feed  # 600 mm/min
    0.01
    """

    def __init__(self, *, start: tuple[float, float] = (0.0, 0.0),
                 arc_tolerance: ArcTolerance | None = None,
                 options: ReaderOptions | None = None):
        try:
            x, y = (float(value) for value in start)
        except (TypeError, ValueError) as exc:
            raise ConfigError("start", f"must be a pair of numbers (m), got {start!r}") from exc
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ConfigError("start", f"must be finite, got {start!r}")
        self.options = options = options or ReaderOptions()
        if arc_tolerance is not None:
            self.options = options = replace(options, arc_tolerance=arc_tolerance)
        self._tolerances = {units: (options.arc_tolerance or ArcTolerance.linuxcnc(units))
                            for units in ("mm", "inch")}
        self._position = (x, y)
        self._z: float | None = None          # machine Z (m), None until a Z word
        self._modal = ModalState()
        self._offsets: dict[int, tuple[float, float, float]] = {   # G54.. → (x, y, z) m
            system: (float(x), float(y), 0.0)
            for system, (x, y) in options.work_offsets.items()}
        self._g92 = (0.0, 0.0, 0.0)
        self._g92_on = False
        self._homes = {"home_g28": (0.0, 0.0), "home_g30": (0.0, 0.0)}
        self._tool = False
        self._spindle_known = False
        self._cycle_p: float | None = None     # a dwell cycle's P, kept from block to block
        self._last_control: tuple[float, float] | None = None   # a G5's second control point
        self.blocks = 0
        """Blocks run so far (lines with at least one word)."""
        self.ended = False
        """True once an M2/M30 has run."""
        self.parameters = Parameters(self._system_parameters())
        """The program's parameters (``#1``, ``#<name>``), shared with the runner."""

    # -- parameters the machine keeps -----------------------------------------------------
    def _system_parameters(self) -> dict:
        unit = self._unit
        table: dict[int | str, object] = {
            "_x": lambda: self._program(0) / unit(),
            "_y": lambda: self._program(1) / unit(),
            "_z": lambda: self._program(2) / unit(),
            "_metric": lambda: float(self._modal.units == "mm"),
            "_imperial": lambda: float(self._modal.units == "inch"),
            "_absolute": lambda: float(self._modal.distance == "absolute"),
            "_incremental": lambda: float(self._modal.distance == "incremental"),
            "_feed": lambda: (self._modal.feed or 0.0) * 60.0 / unit(),
            "_rpm": lambda: self._modal.spindle_speed / RPM,
            "_coord_system": lambda: float(self._modal.coordinate_system),
            "_task": lambda: 1.0,      # the program runs on the machine (not a preview)
            5420: lambda: self._program(0) / unit(),
            5421: lambda: self._program(1) / unit(),
            5422: lambda: self._program(2) / unit(),
            5220: lambda: float(self._modal.coordinate_system),
            5210: lambda: float(self._g92_on),
        }
        for axis in range(3):
            table[5211 + axis] = lambda a=axis: self._g92[a] / unit()
            for system in range(1, 10):
                table[5201 + 20 * system + axis] = \
                    lambda s=system, a=axis: self._offsets.get(s, (0.0,) * 3)[a] / unit()
        for key, base in (("home_g28", 5161), ("home_g30", 5181)):
            for axis in range(2):
                table[base + axis] = lambda k=key, a=axis: self._homes[k][a] / unit()
        return table

    def _unit(self) -> float:
        return INCH if self._modal.units == "inch" else MM

    def _offset(self, axis: int, system: int | None = None) -> float:
        """Machine coordinate of the work zero along ``axis`` (m)."""
        work = self._offsets.get(system or self._modal.coordinate_system, (0.0,) * 3)[axis]
        return work + (self._g92[axis] if self._g92_on else 0.0)

    def _program(self, axis: int) -> float:
        """The position in the program's coordinates (m)."""
        machine = self._position[axis] if axis < 2 else (self._z or 0.0)
        return machine - self._offset(axis) if math.isfinite(machine) else 0.0

    @property
    def state(self) -> ModalState:
        """The modal state in force (immutable snapshot)."""
        return self._modal

    @property
    def position(self) -> tuple[float, float]:
        """The programmed position after the last block, machine coordinates (m)."""
        return self._position

    @property
    def tool_on(self) -> bool:
        """Whether the tool is on (``z = "tool"``)."""
        return self._tool

    def execute(self, text: str, *, line: int = 1) -> tuple[Item, ...]:
        """Run one block of plain words (no parameters or O-words); on error raise
        ``GCodeError`` and change nothing.

        Parameters
        ----------
        text : str
            One line of G-code, without its line break.
        line : int
            Its 1-based line number, stamped on items and errors.

        Returns
        -------
        tuple
            The ``Event``, ``Dwell``, ``PathControl``, ``Move`` and ``ProgramEnd`` items of
            the block, in execution order; empty for a block that only changes modes.
        """
        words = lex(text, line)
        if not words:
            return ()
        return self.execute_words(words, line, text)

    def execute_words(self, words: list[Word], line: int, source: str,
                      file: str | None = None) -> tuple[Item, ...]:
        """Run one block given as its words (values evaluated); all or nothing."""
        block = _read(words, line, source, file, self.options.z)
        saved = (self._modal, self._position, self._z, dict(self._offsets), self._g92,
                 self._g92_on, dict(self._homes), self._tool, self._spindle_known,
                 self._cycle_p, self._last_control)
        try:
            items = self._run(block)
        except BaseException:
            (self._modal, self._position, self._z, self._offsets, self._g92, self._g92_on,
             self._homes, self._tool, self._spindle_known, self._cycle_p,
             self._last_control) = saved
            raise
        self.blocks += 1
        self.ended = self.ended or "stopping" in block.codes
        return tuple(items)

    def fast_line(self, found: re.Match[str], line: int) -> Move | bool | None:
        """The commonest CAM block, ``[N…] [G0|G1] X… Y… [F…]`` in plain words, matched by
        ``FAST_LINE``: the same result as ``execute_words`` (the same arithmetic in the
        same order, so the same floats), without its general machinery.

        Returns
        -------
        Move, True or None
            The block's move; True when it moves nothing (a repeated point); None when the
            block needs the general path (another mode in force, a missing feed, anything
            that may be an error), which then runs it from the start.
        """
        number, g, x, y, f = found.groups()
        if x is None and y is None:
            return None
        modal = self._modal
        motion = modal.motion if g is None else ("rapid" if g == "0" else "line")
        if (motion != "line" and motion != "rapid") or modal.plane != "xy":
            return None
        unit = INCH if modal.units == "inch" else MM
        feed = modal.feed
        if f is not None:
            value = float(f)
            if not value < MAX_VALUE:
                return None
            feed = value * unit / 60.0
        if motion == "line" and not feed:
            return None
        start = self._position
        incremental = modal.distance == "incremental"
        end_x, end_y = start
        if x is not None:
            value = float(x)
            if not -MAX_VALUE < value < MAX_VALUE:
                return None
            end_x = start[0] + value * unit if incremental else value * unit + self._offset(0)
        if y is not None:
            value = float(y)
            if not -MAX_VALUE < value < MAX_VALUE:
                return None
            end_y = start[1] + value * unit if incremental else value * unit + self._offset(1)
        if not (abs(end_x) <= WORKSPACE and abs(end_y) <= WORKSPACE):
            return None
        if motion != modal.motion or feed != modal.feed:
            self._modal = replace(modal, motion=motion, feed=feed)
        self.blocks += 1
        if abs(end_x - start[0]) <= COINCIDENT and abs(end_y - start[1]) <= COINCIDENT:
            return True
        target = self._position = (end_x, end_y)
        return trusted_move(motion, start, target, None if motion == "rapid" else feed, line,
                            None if number is None else int(number))

    # -- one block ------------------------------------------------------------------------
    def _run(self, block: _Block) -> list[Item]:
        """Step 2: what the block means; raises (the caller restores the state)."""
        old, codes, values = self._modal, block.codes, block.values
        changes: dict[str, object] = {
            group: codes[group][0].value
            for group in ("motion", "plane", "distance", "units", "feed_mode", "arc_distance",
                          "coordinate_system", "path") if group in codes
        }
        if codes.get("non_modal", (None,))[0] is not None \
                and codes["non_modal"][0].value in _AXIS_GROUP and "motion" in codes:
            raise block.error(codes["motion"][2], "two G codes that both use the axis words "
                              f"({code_name(*codes['motion'][1])}, "
                              f"{code_name(*codes['non_modal'][1])}): put them in two blocks",
                              "modal-conflict")
        number = None
        if "N" in values:
            number = _whole_number(block, "N", "block number N")
        if "F" in values:    # feed before units, as LinuxCNC: G20 F10 in G21 is 10 mm/min
            changes["feed"] = _at_least_zero(block, "F", "feed F") * old.unit / 60.0
        unit = INCH if changes.get("units", old.units) == "inch" else MM
        items = self._machine_functions(block, old, changes)
        non_modal = codes["non_modal"][0].value if "non_modal" in codes else None
        if non_modal == "dwell":     # then the block's motion, if any (LinuxCNC's order)
            if "P" not in values:
                raise block.error(codes["non_modal"][2], "G4 needs a P word (dwell time, s)",
                                  "missing-word")
            items.append(Dwell(_at_least_zero(block, "P", "dwell time P (s)"), block.line))
        changes = {name: value for name, value in changes.items() if getattr(old, name) != value}
        modal = replace(old, **changes) if changes else old
        self._modal = modal
        claimed = {"N", "F", "S", "T"}
        if "tool_change" in codes and codes["tool_change"][0].value == "set":
            claimed.add("Q")
        if non_modal == "dwell":
            claimed.add("P")
        if "tool_length" in codes:
            claimed.add("H")
        if "path" in codes:
            items.append(self._path_control(block, modal, unit, claimed))
        if non_modal in _AXIS_GROUP:
            items.extend(self._axis_command(block, non_modal, unit, claimed))
        elif non_modal in ("set_g28", "set_g30"):
            self._homes["home_g" + non_modal[5:7]] = self._position
        elif non_modal in ("g92_reset", "g92_off"):
            self._g92_on = False
            if non_modal == "g92_reset":
                self._g92 = (0.0, 0.0, 0.0)
        elif non_modal == "g92_restore":
            self._g92_on = True
        arc = modal.motion == "arc_cw" or modal.motion == "arc_ccw"
        moves = non_modal not in _AXIS_GROUP and (
            "X" in values or "Y" in values or "Z" in values or "@" in values
            or "^" in values or (arc and not values.keys().isdisjoint("IJKR")))
        if moves:
            claimed.update("XYZ@^")
            if arc:
                claimed.update("IJKRP")
                if non_modal == "dwell":
                    raise block.error(values["P"][1] if "P" in values else 1,
                                      "P word claimed by both G4 (dwell) and the arc "
                                      "(turns): put them in two blocks", "ambiguous-word")
            elif modal.motion is not None and modal.motion.startswith("cycle"):
                claimed.update("RQLPK")
            elif modal.motion == "cubic" or modal.motion == "quadratic":
                claimed.update("IJPQ")
            items.extend(self._motion(block, modal, unit, number, non_modal == "machine"))
        for letter in values:
            if letter not in claimed:
                raise block.error(values[letter][1], self._unused(letter), "unused-word")
        if "pause" in codes:
            items.append(Event("pause", codes["pause"][0].value, block.line))
        if "stopping" in codes:
            items.append(ProgramEnd(codes["stopping"][0].value, block.line))
        return items

    @staticmethod
    def _unused(letter: str) -> str:
        uses = {"I": "an arc (G2/G3)", "J": "an arc (G2/G3)", "R": "an arc (G2/G3)",
                "P": "G4, G10, G64 or an arc", "L": "G10", "Q": "G64",
                "H": "G43", "D": "G41/G42", "X": "a motion", "Y": "a motion",
                "Z": "a motion", "@": "a motion", "^": "a motion",
                "K": "an arc in the XZ or YZ plane"}
        return f"{letter} word without {uses.get(letter, 'a command')} to use it"

    def _machine_functions(self, block: _Block, old: ModalState,
                           changes: dict[str, object]) -> list[Item]:
        """Events of S, T, M6, M3/M4/M5, M7/M8/M9 in that order; records them in
        ``changes``; the tool on/off of the spindle with ``z = "tool"``."""
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
        if "tool_change" in codes and codes["tool_change"][0].value == "set":   # M61 Q
            if "Q" not in values:
                raise block.error(codes["tool_change"][2], "M61 needs a Q word (the tool now "
                                  "in the spindle)", "missing-word")
            tool = _whole_number(block, "Q", "M61 Q (tool number)")
            changes["tool"] = tool
            items.append(Event("tool_select", tool, line))
        elif "tool_change" in codes:
            items.append(Event("tool_change", changes.get("tool", old.tool), line))
        for group, kinds in (("spindle", _SPINDLE), ("coolant", _COOLANT)):
            if group in codes:
                changes[group] = codes[group][0].value
                items.append(Event(kinds[codes[group][0].value], None, line))
        if self.options.z == "tool":
            if "spindle" in codes:
                self._spindle_known = True
            self._switch_tool(items, line, changes.get("spindle", old.spindle),
                              changes.get("spindle_speed", old.spindle_speed), self._z)
        return items

    def _switch_tool(self, items: list[Item], line: int, spindle: object, speed: object,
                     z_machine: float | None) -> None:
        """The tool rule of ``ReaderOptions.z = "tool"``; an event when it changes."""
        z_known = z_machine is not None
        if not (z_known or self._spindle_known):
            on = False
        else:
            z_ok = not z_known or z_machine - self._offset(2) <= self.options.tool_z + 1e-12
            spindle_ok = not self._spindle_known or (spindle != "stop" and speed > 0.0)
            on = z_ok and spindle_ok
        if on != self._tool:
            self._tool = on
            items.append(Event("tool_on" if on else "tool_off", None, line))

    def _path_control(self, block: _Block, modal: ModalState, unit: float,
                      claimed: set[str]) -> PathControl:
        values = block.values
        tolerance = merge = None
        if modal.path == "blend":
            claimed.update("PQ")
            if "P" in values:
                tolerance = _at_least_zero(block, "P", "G64 P (blend tolerance)") * unit
            if "Q" in values:
                if "P" not in values:
                    raise block.error(values["Q"][1], "G64 Q (merge tolerance) needs a P "
                                      "(blend tolerance) too", "missing-word")
                merge = _at_least_zero(block, "Q", "G64 Q (merge tolerance)") * unit
        return PathControl(modal.path, tolerance, merge, block.line)

    # -- G10, G28, G30, G92 -----------------------------------------------------------------
    def _axis_command(self, block: _Block, command: str, unit: float,
                      claimed: set[str]) -> list[Item]:
        values, modal = block.values, self._modal
        claimed.update("XYZ")
        given = {axis: values[letter][0] * unit
                 for axis, letter in enumerate("XYZ") if letter in values}
        if command == "set_offsets":
            claimed.update("LP")
            if "L" not in values:
                raise block.error(block.codes["non_modal"][2], "G10 needs an L word (L2 or "
                                  "L20: work offsets)", "missing-word")
            kind = _whole_number(block, "L", "G10 L")
            if kind not in (2, 20):
                raise block.error(values["L"][1], f"G10 L{kind} is not supported (tool "
                                  "tables and fixtures): only G10 L2 and G10 L20 set work "
                                  "offsets", "unsupported")
            if "P" not in values:
                raise block.error(block.codes["non_modal"][2], f"G10 L{kind} needs a P word "
                                  "(coordinate system 1-9, 0: the current one)",
                                  "missing-word")
            system = _whole_number(block, "P", f"G10 L{kind} P", most=9) \
                or modal.coordinate_system
            offsets = list(self._offsets.get(system, (0.0,) * 3))
            for axis, value in given.items():
                if kind == 2:
                    offsets[axis] = value
                else:   # L20: the current position becomes ``value`` in that system
                    machine = self._position[axis] if axis < 2 else (self._z or 0.0)
                    g92 = self._g92[axis] if self._g92_on else 0.0
                    offsets[axis] = machine - g92 - value
            self._offsets[system] = tuple(offsets)
        elif command == "g92":
            if not given:
                raise block.error(block.codes["non_modal"][2], "G92 needs an axis word",
                                  "missing-word")
            g92 = list(self._g92 if self._g92_on else (0.0, 0.0, 0.0))
            for axis, value in given.items():
                machine = self._position[axis] if axis < 2 else (self._z or 0.0)
                work = self._offsets.get(modal.coordinate_system, (0.0,) * 3)[axis]
                g92[axis] = machine - work - value
            self._g92, self._g92_on = tuple(g92), True
        else:
            return self._home(block, command, given)
        return []

    def _home(self, block: _Block, command: str, given: dict[int, float]) -> list[Item]:
        """G28/G30: rapid to the given axes' point, then home along those axes (all with
        none given)."""
        modal, start = self._modal, self._position
        via = list(start)
        for axis, value in given.items():
            if axis < 2:
                via[axis] = (start[axis] + value if modal.distance == "incremental"
                             else value + self._offset(axis))
        home = self._homes[command]
        end = [home[axis] if (not given or axis in given) else via[axis] for axis in range(2)]
        items: list[Item] = []
        if 2 in given or not given:
            if self.options.z == "tool" and self._z is not None:
                self._switch_tool(items, block.line, modal.spindle, modal.spindle_speed,
                                  math.inf)
            self._z = None if self._z is None else math.inf
        for a, b in ((start, via), (via, end)):
            a, b = (a[0], a[1]), (b[0], b[1])
            if abs(a[0] - b[0]) > COINCIDENT or abs(a[1] - b[1]) > COINCIDENT:
                items.append(Move("rapid", a, b, None, line=block.line))
        self._position = (end[0], end[1])
        return items

    # -- motion ---------------------------------------------------------------------------
    def _target(self, block: _Block, modal: ModalState, unit: float,
                machine: bool) -> tuple[tuple[float, float], float | None]:
        values = block.values
        start = self._position
        end = [*start]
        if "@" in values or "^" in values:
            self._polar(block, modal, unit, end)
        for axis, letter in enumerate("XY"):
            if letter in values:
                value = values[letter][0] * unit
                if modal.distance == "incremental":
                    end[axis] = start[axis] + value
                else:
                    end[axis] = value + (0.0 if machine else self._offset(axis))
        z = self._z
        if "Z" in values:
            value = values["Z"][0] * unit
            if modal.distance == "incremental":
                z = (z or 0.0) + value
            else:
                z = value + (0.0 if machine else self._offset(2))
        if not (abs(end[0]) <= WORKSPACE and abs(end[1]) <= WORKSPACE):
            raise block.error(block.column("X", "Y"), f"end point ({end[0] / MM:.6g}, "
                              f"{end[1] / MM:.6g}) mm is beyond ±{WORKSPACE / MM:g} mm",
                              "out-of-range")
        if abs(end[0] - start[0]) <= COINCIDENT and abs(end[1] - start[1]) <= COINCIDENT:
            end = [*start]
        return (end[0], end[1]), z

    def _polar(self, block: _Block, modal: ModalState, unit: float, end: list[float]) -> None:
        """``@`` (distance) and ``^`` (angle, degrees) about the work origin, as LinuxCNC:
        in G90 they are the end point's polar coordinates, in G91 they add to those of the
        current point."""
        values = block.values
        for letter in "XY":
            if letter in values:
                raise block.error(values[letter][1], f"{letter} word with polar words (@, ^):"
                                  " program the end point one way", "ambiguous-word")
        x, y = self._program(0), self._program(1)
        radius, angle = math.hypot(x, y), math.degrees(math.atan2(y, x))
        distance = values["@"][0] * unit if "@" in values else None
        turn = values["^"][0] if "^" in values else None
        if modal.distance == "incremental":
            if x == 0.0 and y == 0.0:
                raise block.error(block.column("@", "^"), "incremental polar words (G91 @ ^) "
                                  "at the work origin: the angle there is undefined",
                                  "bad-value")
            radius += distance or 0.0
            angle += turn or 0.0
        else:
            radius = radius if distance is None else distance
            angle = angle if turn is None else turn
        end[0] = radius * math.cos(math.radians(angle)) + self._offset(0)
        end[1] = radius * math.sin(math.radians(angle)) + self._offset(1)

    def _motion(self, block: _Block, modal: ModalState, unit: float, number: int | None,
                machine: bool) -> list[Item]:
        """The moves of a block with axis (or arc centre) words, and the new position."""
        values = block.values
        written_motion = block.codes.get("motion")
        column = (written_motion[2] if written_motion is not None
                  else block.column("X", "Y", "Z", "I", "J", "R"))
        motion = modal.motion
        if motion is None:
            raise block.error(block.column("X", "Y", "Z"), "axis words without a motion mode "
                              "in force: program G0, G1, G2 or G3", "no-motion-mode")
        if motion.startswith("cycle"):
            return self._cycle(block, modal, unit, column)
        if motion == "cubic" or motion == "quadratic":
            return self._spline(block, modal, unit, number, column)
        self._last_control = None
        name = _WRITTEN[motion]
        if modal.plane != "xy":
            plane = {"xz": "G18", "yz": "G19"}[modal.plane]
            raise block.error(column, f"this machine has only the XY plane ({plane} is in "
                                      f"force): program G17", "plane")
        if machine and motion not in ("rapid", "line"):
            raise block.error(block.codes["non_modal"][2], "G53 works only with G0 or G1",
                              "modal-conflict")
        start = self._position
        target, z = self._target(block, modal, unit, machine)
        feed = None if motion == "rapid" else modal.feed
        if motion != "rapid" and not feed:
            if feed is None:
                raise block.error(column, f"{name} needs a feed: no F word programmed yet",
                                  "missing-feed")
            raise block.error(values["F"][1] if "F" in values else column,
                              f"{name} with zero feed (F0)", "zero-feed")
        items: list[Item] = []
        if "Z" in values:
            if self.options.z == "tool":
                self._switch_tool(items, block.line, modal.spindle, modal.spindle_speed, z)
            self._z = z
        self._position = target
        if motion == "rapid" or motion == "line":
            if target != start:
                items.append(Move(motion, start, target, feed, line=block.line,
                                  block_number=number))
            return items
        if target == start and "Z" in values and not ("I" in values or "J" in values
                                                       or "R" in values):
            return items    # a Z-only block in an arc mode
        items.extend(self._arc(block, motion, start, target, feed, unit, number, column))
        return items

    def _spline(self, block: _Block, modal: ModalState, unit: float, number: int | None,
                column: int) -> list[Item]:
        """G5 (cubic Bézier: I, J from the start to the first control point, P, Q from the
        end to the second; after a G5, I and J may be left out and the first control point
        mirrors the last one) or G5.1 (quadratic: I, J from the start to the control
        point), run as feed lines within ``SPLINE_TOLERANCE`` of the curve."""
        values, name = block.values, _WRITTEN[modal.motion]
        if modal.plane != "xy":
            raise block.error(column, f"{name} runs only in the XY plane (G17)", "plane")
        feed = modal.feed
        if not feed:
            raise block.error(column, f"{name} needs a feed: no F word programmed yet"
                              if feed is None else f"{name} with zero feed (F0)",
                              "missing-feed" if feed is None else "zero-feed")
        start = self._position
        target, _ = self._target(block, modal, unit, False)
        if modal.motion == "quadratic":
            if "I" not in values or "J" not in values:
                raise block.error(column, "G5.1 needs I and J (the control point, from the "
                                  "start)", "missing-word")
            control = (start[0] + values["I"][0] * unit, start[1] + values["J"][0] * unit)
            # the quadratic as a cubic: control points 2/3 of the way to the quadratic's
            points = (start, (start[0] + 2.0 / 3.0 * (control[0] - start[0]),
                              start[1] + 2.0 / 3.0 * (control[1] - start[1])),
                      (target[0] + 2.0 / 3.0 * (control[0] - target[0]),
                       target[1] + 2.0 / 3.0 * (control[1] - target[1])), target)
            self._last_control = None
        else:
            if "P" not in values or "Q" not in values:
                raise block.error(column, "G5 needs P and Q (the second control point, from "
                                  "the end)", "missing-word")
            if "I" in values and "J" in values:
                first = (start[0] + values["I"][0] * unit, start[1] + values["J"][0] * unit)
            elif "I" in values or "J" in values:
                raise block.error(block.column("I", "J"), "G5 needs both I and J, or neither "
                                  "after a G5", "missing-word")
            elif self._last_control is not None:
                first = (2.0 * start[0] - self._last_control[0],
                         2.0 * start[1] - self._last_control[1])
            else:
                raise block.error(column, "G5 needs I and J unless it follows a G5",
                                  "missing-word")
            second = (target[0] + values["P"][0] * unit, target[1] + values["Q"][0] * unit)
            points = (start, first, second, target)
            self._last_control = second
        self._position = target
        ends = bezier_chords(points, SPLINE_TOLERANCE)
        moves: list[Item] = []
        for a, b in itertools.pairwise([start, *ends]):
            if a != b:
                moves.append(Move("line", a, b, feed, line=block.line, block_number=number))
        return moves

    def _cycle(self, block: _Block, modal: ModalState, unit: float,
               column: int) -> list[Item]:
        """A canned cycle (G73, G81–G89) on this machine: its holes' XY positions, reached
        by rapids, L times (in G91 each repeat moves on by X, Y or the polar words); at each
        hole the plunge is the tool on and off (``z = "tool"``) and G82, G86, G88, G89 dwell
        P seconds. Its Z moves are not run: Z is ignored or the tool."""
        values, name = block.values, "G" + modal.motion[7:]
        if self.options.z == "error":
            raise block.error(column, f"canned cycles ({name}) drill along Z: set "
                              "controller.gcode.z = \"ignore\" or \"tool\" to run their "
                              "moves between the holes", "unsupported")
        if modal.plane != "xy":
            raise block.error(column, "canned cycles run only in the XY plane (G17)", "plane")
        repeats = _whole_number(block, "L", f"{name} L (repeats)", least=1) \
            if "L" in values else 1
        if "P" in values:                   # sticky, as LinuxCNC's cycle_p
            self._cycle_p = _at_least_zero(block, "P", f"{name} P (dwell, s)")
        dwell = self._cycle_p if name in ("G82", "G86", "G88", "G89") else None
        items: list[Item] = []
        for _ in range(repeats):
            start = self._position
            target, _ = self._target(block, modal, unit, False)
            if target != start:
                items.append(Move("rapid", start, target, None, line=block.line))
            self._position = target
            plunge = self.options.z == "tool" and not self._tool
            if plunge:
                items.append(Event("tool_on", None, block.line))
            if dwell is not None:
                items.append(Dwell(dwell, block.line))
            if plunge:
                items.append(Event("tool_off", None, block.line))
        return items

    def _arc(self, block: _Block, motion: str, start: tuple[float, float],
             target: tuple[float, float], feed: float, unit: float, number: int | None,
             column: int) -> list[Move]:
        """The G2/G3 moves from ``start`` to ``target``: turns, centre, tolerance checks."""
        values, name, modal = block.values, _WRITTEN[motion], self._modal
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
        tolerance = self._tolerances[modal.units]
        try:
            if "R" in values:
                pieces = [(start, target,
                           center_from_radius(start, target, values["R"][0] * unit, ccw=ccw,
                                              tolerance=tolerance))]
            else:
                if modal.arc_distance == "absolute":
                    programmed = tuple(
                        values[letter][0] * unit + self._offset(axis) if letter in values
                        else start[axis] for axis, letter in enumerate("IJ"))
                else:
                    programmed = tuple(
                        start[axis] + values[letter][0] * unit if letter in values
                        else start[axis] for axis, letter in enumerate("IJ"))
                pieces = center_from_offset(start, target, programmed, ccw=ccw, turns=turns,
                                            tolerance=tolerance)
        except ArcError as exc:
            raise block.error(column, exc.message, exc.code) from None
        if len(pieces) == 1:
            return [Move("arc", start, target, feed, pieces[0][2], ccw, turns, block.line,
                         number)]
        return [Move("arc", p, q, feed, c, ccw, 0, block.line, number) for p, q, c in pieces]
