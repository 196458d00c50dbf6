"""Run by the Python that has LinuxCNC's ``gcode`` module (Debian's system python3, not the
venv): read one program with LinuxCNC's interpreter and print its canonical moves at full
double precision, one JSON list per line.

``rs274 -g`` prints 4 decimals; the interpreter's Python binding (the one AXIS previews
with) hands the canonical calls over as doubles, in inches, relative to the work offsets it
reports. Each output line is ``[kind, x, y, cx, cy, rotation]`` in inches, machine
coordinates (offsets and the XY rotation applied as AXIS's ``Translated`` does), with ``cx``,
``cy`` and ``rotation`` null for straight moves; ``kind`` is ``rapid``, ``line``, ``arc`` or
``spline`` (a NURBS/G5 move, end unknown). Each SET_FEED_RATE call is a line
``["feed", value]``, per minute, in inches or the program's unit (see ``_make_precise``). A
last line ``["end", result]`` carries the interpreter's exit code.
Usage: ``python3 linuxcnc_canon.py FILE``, run in the file's folder.
"""

import json
import math
import sys

import gcode  # LinuxCNC's interpreter binding (linuxcnc-uspace)


class Canon:
    """The canonical-call sink ``gcode.parse`` drives; only what the moves need is kept."""

    parameter_file = ""

    def __init__(self):
        self.g5x = (0.0, 0.0)
        self.g92 = (0.0, 0.0)
        self.rotation = 0.0
        self.position = (0.0, 0.0)

    def _machine(self, x, y):
        x, y = x + self.g92[0], y + self.g92[1]
        if self.rotation:
            t = math.radians(self.rotation)
            x, y = x * math.cos(t) - y * math.sin(t), x * math.sin(t) + y * math.cos(t)
        return x + self.g5x[0], y + self.g5x[1]

    def _emit(self, *row):
        print(json.dumps(row))

    # moves ---------------------------------------------------------------------------------
    def straight_traverse(self, x, y, *rest):
        self._straight("rapid", x, y)

    def straight_feed(self, x, y, *rest):
        self._straight("line", x, y)

    def _straight(self, kind, x, y):
        end = self._machine(x, y)
        if end != self.position:                 # a Z-only move has no XY motion
            self._emit(kind, end[0], end[1], None, None, None)
        self.position = end

    def arc_feed(self, x, y, cx, cy, rotation, *rest):
        end, centre = self._machine(x, y), self._machine(cx, cy)
        self._emit("arc", end[0], end[1], centre[0], centre[1], rotation)
        self.position = end

    def nurbs_feed(self, *args):
        self._emit("spline", None, None, None, None, None)
        self.position = (math.nan, math.nan)

    def set_feed_rate(self, feed):
        self._emit("feed", feed)

    def straight_probe(self, *args):
        self._emit("probe", None, None, None, None, None)

    # state ---------------------------------------------------------------------------------
    def set_g5x_offset(self, index, x, y, *rest):
        self.g5x = (x, y)

    def set_g92_offset(self, x, y, *rest):
        self.g92 = (x, y)

    def set_xy_rotation(self, theta):
        self.rotation = theta

    # what the interpreter asks ---------------------------------------------------------------
    def get_external_length_units(self):
        return 1.0 / 25.4

    def get_external_angular_units(self):
        return 1.0

    def get_axis_mask(self):
        return 0x1FF

    def get_block_delete(self):
        return 0

    def get_tool(self, index):
        return (-1,) + (0.0,) * 12 + (0,)

    def check_abort(self):
        return False

    def next_line(self, state):
        pass

    def __getattr__(self, name):
        """Every other canonical call (spindle, coolant, comments...) is ignored."""
        if name.startswith("__"):
            raise AttributeError(name)
        return lambda *args: None


if __name__ == "__main__":
    result, _ = gcode.parse(sys.argv[1], Canon(), "G21", "")   # rs274 starts in mm
    print(json.dumps(["end", result]))
