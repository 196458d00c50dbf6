"""LinuxCNC's own interpreter as a reference: run ``rs274 -g`` and read its canonical calls.

``rs274`` (Debian's ``linuxcnc-uspace``, ``make test-linuxcnc`` installs it) prints one
canonical machining call per line, e.g. ``STRAIGHT_FEED(10.0000, 5.0000, 0.0000, ...)``,
with coordinates in the program's current units relative to the work offsets, which it
reports as ``SET_G5X_OFFSET`` and ``SET_G92_OFFSET`` calls. ``canonical_moves`` turns them
into machine-coordinate moves in SI, the form of ``twin.controller.gcode.Move``.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from twin.units import INCH, MM

RS274 = shutil.which("rs274")

PRINTED = 0.5e-4
"""rs274 prints 4 decimals: a coordinate is known to half a unit of the 4th (program units)."""

_READ = {"USE_LENGTH_UNITS", "SET_FEED_RATE", "SET_G5X_OFFSET", "SET_G92_OFFSET",
         "STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED", "NURBS_FEED"}
_CALL = re.compile(r"^\s*\d+\s+N\S*\s+([A-Z_0-9]+)\((.*)\)\s*$")


@dataclass
class CanonMove:
    kind: str                       # "rapid", "line", "arc", "spline" (end unknown)
    end: tuple[float, float]        # machine coordinates (m)
    feed: float | None              # m/s
    center: tuple[float, float] | None = None
    ccw: bool = False
    turns: int = 0
    unit: float = MM                # the program unit the numbers were printed in
    unsure: bool = False            # after a spline: may be a Z-only move (XY unknown)


@dataclass
class Reference:
    moves: list[CanonMove]
    error: str | None               # rs274's message when it stopped on an error
    error_block: str | None         # the block it stopped at
    other_axes: bool = False        # a move of A, B, C (U, V, W), or a probe


def _numbers(args: str) -> list[float]:
    return [float(part) for part in (p.strip() for p in args.split(","))
            if re.fullmatch(r"[-+]?[0-9]*\.?[0-9]+", part)]


def run_rs274(path: Path) -> Reference:
    """Run LinuxCNC's interpreter on ``path``; its moves in SI machine coordinates."""
    done = subprocess.run([RS274, "-g", str(path)], capture_output=True, text=True,
                          timeout=60, stdin=subprocess.DEVNULL, cwd=path.parent,
                          errors="replace")
    other = False
    unit, feed = MM, None
    g5x, g92 = (0.0, 0.0), (0.0, 0.0)
    position = (0.0, 0.0)               # where the program starts, as parse() does
    moves: list[CanonMove] = []
    lines = done.stdout.splitlines()
    for row in lines:
        found = _CALL.match(row)
        if found is None:
            continue
        name, args = found.groups()
        if name == "STRAIGHT_PROBE":
            other = True
        if name not in _READ:
            continue
        values = _numbers(args)
        if name == "NURBS_FEED":              # G5/G5.1: rs274 prints no end point
            moves.append(CanonMove("spline", (math.nan, math.nan), feed, unit=unit))
            position = (math.nan, math.nan)
            continue
        if name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED"):
            rest = values[3:] if name != "ARC_FEED" else values[6:]
            other = other or any(value != 0.0 for value in rest)
        if name == "USE_LENGTH_UNITS":
            unit = INCH if "INCHES" in args else MM
        elif name == "SET_FEED_RATE":
            feed = values[0] * unit / 60.0
        elif name == "SET_G5X_OFFSET":
            g5x = (values[1] * unit, values[2] * unit)
        elif name == "SET_G92_OFFSET":
            g92 = (values[0] * unit, values[1] * unit)
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED"):
            end = (values[0] * unit + g5x[0] + g92[0], values[1] * unit + g5x[1] + g92[1])
            if name == "ARC_FEED":
                center = (values[2] * unit + g5x[0] + g92[0],
                          values[3] * unit + g5x[1] + g92[1])
                rotation = int(values[4])
                moves.append(CanonMove("arc", end, feed, center, rotation > 0,
                                       abs(rotation) - 1, unit))
            else:
                if end == position:
                    continue                       # a Z-only move: no XY motion
                moves.append(CanonMove("rapid" if name == "STRAIGHT_TRAVERSE" else "line",
                                       end, None if name == "STRAIGHT_TRAVERSE" else feed,
                                       unit=unit, unsure=math.isnan(position[0])))
            position = end
    error = block = None
    if done.returncode != 0:
        said = [row.strip() for row in done.stderr.splitlines()
                if row.strip() and row.strip() != "executing"]
        error = said[0] if said else f"rs274 exited {done.returncode}"
        block = said[-1] if len(said) > 1 else ""
    return Reference(moves, error, block, other)
