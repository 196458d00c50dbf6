"""The motion of a block: end points (cartesian, polar, offsets), lines, arcs, splines,
canned cycles. ``Motion`` is the interpreter's mixin for it: it reads and sets the state the
``Interpreter`` keeps (position, Z, offsets, modal state, the tool), nothing of its own.
"""

from __future__ import annotations

import itertools
import math

from twin.controller.gcode.arcs import ArcError, center_from_offset, center_from_radius
from twin.controller.gcode.block import (
    COINCIDENT,
    WORKSPACE,
    WRITTEN,
    Block,
    at_least_zero,
    whole_number,
)
from twin.controller.gcode.items import Dwell, Event, Item, Move
from twin.controller.gcode.modal import ModalState
from twin.controller.gcode.splines import SPLINE_TOLERANCE, bezier_chords
from twin.units import MM

__all__ = ["Motion"]


class Motion:
    """Mixin of ``Interpreter``: the moves of a block with axis (or arc centre) words."""

    # provided by the Interpreter
    _position: tuple[float, float]
    _z: float | None
    _tool: bool
    _cycle_p: float | None
    _last_control: tuple[float, float] | None

    def _target(self, block: Block, modal: ModalState, unit: float,
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

    def _polar(self, block: Block, modal: ModalState, unit: float, end: list[float]) -> None:
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

    def _motion(self, block: Block, modal: ModalState, unit: float, number: int | None,
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
        name = WRITTEN[motion]
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

    def _spline(self, block: Block, modal: ModalState, unit: float, number: int | None,
                column: int) -> list[Item]:
        """G5 (cubic Bézier: I, J from the start to the first control point, P, Q from the
        end to the second; after a G5, I and J may be left out and the first control point
        mirrors the last one) or G5.1 (quadratic: I, J from the start to the control
        point), run as feed lines within ``SPLINE_TOLERANCE`` of the curve."""
        values, name = block.values, WRITTEN[modal.motion]
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

    def _cycle(self, block: Block, modal: ModalState, unit: float,
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
        repeats = whole_number(block, "L", f"{name} L (repeats)", least=1) \
            if "L" in values else 1
        if "P" in values:                   # sticky, as LinuxCNC's cycle_p
            self._cycle_p = at_least_zero(block, "P", f"{name} P (dwell, s)")
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

    def _arc(self, block: Block, motion: str, start: tuple[float, float],
             target: tuple[float, float], feed: float, unit: float, number: int | None,
             column: int) -> list[Move]:
        """The G2/G3 moves from ``start`` to ``target``: turns, centre, tolerance checks."""
        values, name, modal = block.values, WRITTEN[motion], self._modal
        ccw = motion == "arc_ccw"
        turns = 0
        if "P" in values:
            turns = whole_number(block, "P", "arc P (number of turns)", least=1) - 1
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
