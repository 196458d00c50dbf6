"""The words of a block that are not its motion: machine functions (S, T, M6, M3-M5,
M7-M9, and the tool on/off of a pen or laser machine), path control (G61, G61.1, G64 P Q),
work offsets and homing (G10 L2/L20, G92, G28, G30). ``Commands`` is the interpreter's mixin
for them, as ``Motion`` is for the moves: it reads and sets the state the ``Interpreter``
keeps, nothing of its own.
"""

from __future__ import annotations

import math

from twin.controller.gcode.block import COINCIDENT, Block, at_least_zero, whole_number
from twin.controller.gcode.items import Event, Item, Move, PathControl
from twin.controller.gcode.modal import ModalState
from twin.units import RPM

__all__ = ["AXIS_GROUP", "Commands"]

_SPINDLE = {"cw": "spindle_cw", "ccw": "spindle_ccw", "stop": "spindle_stop"}
_COOLANT = {"mist": "coolant_mist", "flood": "coolant_flood", "off": "coolant_off"}
AXIS_GROUP = ("set_offsets", "home_g28", "home_g30", "g92")
"""Non-modal codes that take the block's axis words instead of a motion."""


class Commands:
    """Mixin of ``Interpreter``: a block's machine functions, path control, offsets and
    homing."""

    # provided by the Interpreter (and ``options``, its ReaderOptions)
    _modal: ModalState
    _position: tuple[float, float]
    _z: float | None
    _tool: bool
    _spindle_known: bool
    _offsets: dict[int, tuple[float, float, float]]
    _g92: tuple[float, float, float]
    _g92_on: bool
    _homes: dict[str, tuple[float, float]]

    def _machine_functions(self, block: Block, old: ModalState,
                           changes: dict[str, object]) -> list[Item]:
        """Events of S, T, M6, M3/M4/M5, M7/M8/M9 in that order; records them in
        ``changes``; the tool on/off of the spindle with ``z = "tool"``."""
        codes, values, line = block.codes, block.values, block.line
        items: list[Item] = []
        if "S" in values:
            speed = at_least_zero(block, "S", "spindle speed S") * RPM
            changes["spindle_speed"] = speed
            items.append(Event("spindle_speed", speed, line))
        if "T" in values:
            tool = whole_number(block, "T", "tool number T")
            changes["tool"] = tool
            items.append(Event("tool_select", tool, line))
        if "tool_change" in codes and codes["tool_change"][0].value == "set":   # M61 Q
            if "Q" not in values:
                raise block.error(codes["tool_change"][2], "M61 needs a Q word (the tool now "
                                  "in the spindle)", "missing-word")
            tool = whole_number(block, "Q", "M61 Q (tool number)")
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

    def _path_control(self, block: Block, modal: ModalState, unit: float,
                      claimed: set[str]) -> PathControl:
        values = block.values
        tolerance = merge = None
        if modal.path == "blend":
            claimed.update("PQ")
            if "P" in values:
                tolerance = at_least_zero(block, "P", "G64 P (blend tolerance)") * unit
            if "Q" in values:
                if "P" not in values:
                    raise block.error(values["Q"][1], "G64 Q (merge tolerance) needs a P "
                                      "(blend tolerance) too", "missing-word")
                merge = at_least_zero(block, "Q", "G64 Q (merge tolerance)") * unit
        return PathControl(modal.path, tolerance, merge, block.line)

    # -- G10, G28, G30, G92 -----------------------------------------------------------------
    def _axis_command(self, block: Block, command: str, unit: float,
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
            kind = whole_number(block, "L", "G10 L")
            if kind not in (2, 20):
                raise block.error(values["L"][1], f"G10 L{kind} is not supported (tool "
                                  "tables and fixtures): only G10 L2 and G10 L20 set work "
                                  "offsets", "unsupported")
            if "P" not in values:
                raise block.error(block.codes["non_modal"][2], f"G10 L{kind} needs a P word "
                                  "(coordinate system 1-9, 0: the current one)",
                                  "missing-word")
            system = whole_number(block, "P", f"G10 L{kind} P", most=9) \
                or modal.coordinate_system
            offsets = list(self._offsets.get(system, (0.0,) * 3))
            for axis, value in given.items():
                if kind == 2:
                    offsets[axis] = value
                else:   # L20: the current position becomes ``value`` in that system
                    machine = self._machine(axis)
                    g92 = self._g92[axis] if self._g92_on else 0.0
                    offsets[axis] = machine - g92 - value
            self._offsets[system] = tuple(offsets)
        elif command == "g92":
            if not given:
                raise block.error(block.codes["non_modal"][2], "G92 needs an axis word",
                                  "missing-word")
            g92 = list(self._g92 if self._g92_on else (0.0, 0.0, 0.0))
            for axis, value in given.items():
                machine = self._machine(axis)
                work = self._offsets.get(modal.coordinate_system, (0.0,) * 3)[axis]
                g92[axis] = machine - work - value
            self._g92, self._g92_on = tuple(g92), True
        else:
            return self._home(block, command, given)
        return []

    def _home(self, block: Block, command: str, given: dict[int, float]) -> list[Item]:
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
