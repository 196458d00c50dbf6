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

import math
import re
from dataclasses import dataclass, field, replace

from twin.controller.gcode.arcs import ArcTolerance
from twin.controller.gcode.block import (
    COINCIDENT,
    WORKSPACE,
    Block,
    at_least_zero,
    read_block,
    whole_number,
)
from twin.controller.gcode.commands import AXIS_GROUP, Commands
from twin.controller.gcode.flow import Limits
from twin.controller.gcode.items import (
    Dwell,
    Event,
    Item,
    Move,
    ProgramEnd,
    trusted_move,
)
from twin.controller.gcode.lexer import MAX_VALUE, Word, lex
from twin.controller.gcode.modal import ModalState, code_name
from twin.controller.gcode.motion import Motion
from twin.controller.gcode.parameters import Parameters
from twin.errors import ConfigError
from twin.units import INCH, MM, RPM

__all__ = ["COINCIDENT", "FAST_LINE", "ORDER", "WORKSPACE", "Interpreter", "ReaderOptions"]

_NUMBER = r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)"
FAST_LINE = re.compile(rf"(?:[Nn]([0-9]+) ?)?(?:[Gg]0?([01]) ?)?(?:[Xx]({_NUMBER}) ?)?"
                       rf"(?:[Yy]({_NUMBER}) ?)?(?:[Ff]([0-9]+\.?[0-9]*|\.[0-9]+))? *")
"""The commonest line of CAM output, ``[N…] [G0|G1] X… Y… [F…]``: ``Interpreter.fast_line``
runs it."""

_NO_OFFSET = (0.0, 0.0, 0.0)
"""The offsets of a coordinate system never set (m)."""

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

_Z_MODES = ("error", "ignore", "tool")
_BLOCK_STATE = ("_modal", "_position", "_z", "_offsets", "_g92", "_g92_on", "_homes",
                "_tool", "_spindle_known", "_cycle_p", "_last_control")
"""What a block may change: restored when it fails (a bad block changes nothing)."""


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


class Interpreter(Motion, Commands):
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
        def unit() -> float:
            return self._modal.unit
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

    def _offset(self, axis: int) -> float:
        """Machine coordinate of the work zero along ``axis`` (m)."""
        work = self._offsets.get(self._modal.coordinate_system, _NO_OFFSET)[axis]
        return work + (self._g92[axis] if self._g92_on else 0.0)

    def _machine(self, axis: int) -> float:
        """The position along ``axis`` (0, 1, 2 = X, Y, Z) in machine coordinates (m)."""
        return self._position[axis] if axis < 2 else (self._z or 0.0)

    def _program(self, axis: int) -> float:
        """The position in the program's coordinates (m)."""
        machine = self._machine(axis)
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
        block = read_block(words, line, source, file, self.options.z)
        saved = {name: getattr(self, name) for name in _BLOCK_STATE}
        saved["_offsets"], saved["_homes"] = dict(self._offsets), dict(self._homes)
        try:
            items = self._run(block)
        except BaseException:
            for name, value in saved.items():
                setattr(self, name, value)
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
        return self.fast_move(None if number is None else float(number),  # any length
                              None if g is None else float(g),
                              None if x is None else float(x),
                              None if y is None else float(y),
                              None if f is None else float(f), line)

    def fast_move(self, number: float | None, g: float | None, x: float | None,
                  y: float | None, f: float | None, line: int) -> Move | bool | None:
        """``fast_line`` on the words' values: a block of only N, G, X, Y and F words (the
        parameterised lines ``twin.controller.gcode.shapes`` compiles come here too).
        Returns as ``fast_line``; None also for a G other than G0/G1, a negative or zero
        feed word, a block number that is not a whole number."""
        if x is None and y is None:
            return None
        modal = self._modal
        if g is None:
            motion = modal.motion
        elif g == 1.0:
            motion = "line"
        elif g == 0.0:
            motion = "rapid"
        else:
            return None
        if (motion != "line" and motion != "rapid") or modal.plane != "xy":
            return None
        unit = modal.unit
        feed = modal.feed
        if f is not None:
            if not 0.0 <= f < MAX_VALUE:
                return None
            feed = f * unit / 60.0
        if motion == "line" and not feed:
            return None
        start = self._position
        incremental = modal.distance == "incremental"
        end_x, end_y = start
        if x is not None:
            if not -MAX_VALUE < x < MAX_VALUE:
                return None
            end_x = start[0] + x * unit if incremental else x * unit + self._offset(0)
        if y is not None:
            if not -MAX_VALUE < y < MAX_VALUE:
                return None
            end_y = start[1] + y * unit if incremental else y * unit + self._offset(1)
        if not (abs(end_x) <= WORKSPACE and abs(end_y) <= WORKSPACE):
            return None
        if number is not None:
            if not 0.0 <= number < MAX_VALUE or number != int(number):
                return None
            number = int(number)
        if motion != modal.motion or feed != modal.feed:
            self._modal = replace(modal, motion=motion, feed=feed)
        self.blocks += 1
        if abs(end_x - start[0]) <= COINCIDENT and abs(end_y - start[1]) <= COINCIDENT:
            return True
        target = self._position = (end_x, end_y)
        return trusted_move(motion, start, target, None if motion == "rapid" else feed, line,
                            number)

    # -- one block ------------------------------------------------------------------------
    def _run(self, block: Block) -> list[Item]:
        """Step 2: what the block means; raises (the caller restores the state)."""
        old, codes, values = self._modal, block.codes, block.values
        changes: dict[str, object] = {
            group: codes[group][0].value
            for group in ("motion", "plane", "distance", "units", "feed_mode", "arc_distance",
                          "coordinate_system", "path") if group in codes
        }
        if codes.get("non_modal", (None,))[0] is not None \
                and codes["non_modal"][0].value in AXIS_GROUP and "motion" in codes:
            raise block.error(codes["motion"][2], "two G codes that both use the axis words "
                              f"({code_name(*codes['motion'][1])}, "
                              f"{code_name(*codes['non_modal'][1])}): put them in two blocks",
                              "modal-conflict")
        number = None
        if "N" in values:
            number = whole_number(block, "N", "block number N")
        if "F" in values:    # feed before units, as LinuxCNC: G20 F10 in G21 is 10 mm/min
            changes["feed"] = at_least_zero(block, "F", "feed F") * old.unit / 60.0
        unit = INCH if changes.get("units", old.units) == "inch" else MM
        items = self._machine_functions(block, old, changes)
        non_modal = codes["non_modal"][0].value if "non_modal" in codes else None
        if non_modal == "dwell":     # then the block's motion, if any (LinuxCNC's order)
            if "P" not in values:
                raise block.error(codes["non_modal"][2], "G4 needs a P word (dwell time, s)",
                                  "missing-word")
            items.append(Dwell(at_least_zero(block, "P", "dwell time P (s)"), block.line))
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
        if non_modal in AXIS_GROUP:
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
        moves = non_modal not in AXIS_GROUP and (
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

    # -- motion ---------------------------------------------------------------------------
