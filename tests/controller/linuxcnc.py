"""LinuxCNC's own interpreter as a reference: run ``rs274 -g`` and read its canonical calls.

``rs274`` (Debian's ``linuxcnc-uspace``, ``make test-linuxcnc`` installs it) prints one
canonical machining call per line, e.g. ``STRAIGHT_FEED(10.0000, 5.0000, 0.0000, ...)``,
with coordinates in the program's current units relative to the work offsets, which it
reports as ``SET_G5X_OFFSET`` and ``SET_G92_OFFSET`` calls. ``run_rs274`` turns them
into machine-coordinate moves in SI, the form of ``twin.controller.gcode.Move``.

rs274 prints 4 decimals. The same package ships the interpreter's Python binding (the
``gcode`` module AXIS previews with, importable by the system ``python3``), which hands the
same calls over as doubles: ``linuxcnc_canon.py`` runs it, and ``run_rs274`` puts its end
points and centres, at full precision, in place of the printed ones (``Reference.precise``).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from twin.units import INCH, MM

RS274 = shutil.which("rs274")


def _binding_python() -> str | None:
    """A Python that imports LinuxCNC's ``gcode`` module: Debian's own python3."""
    for python in ("/usr/bin/python3", shutil.which("python3")):
        if python and subprocess.run([python, "-c", "import gcode"], capture_output=True,
                                     timeout=30).returncode == 0:
            return python
    return None


BINDING = _binding_python() if RS274 else None

_HOME = tempfile.TemporaryDirectory(prefix="rs274-home-")
ENV = {**os.environ, "HOME": _HOME.name}
"""rs274 and the binding keep their tool table in ``$HOME/.tool.mmap``, which each run
truncates and maps shared: two runs at once over one file crash with SIGBUS (two test
sessions side by side did). Each test process gives them a home of its own."""
_VARS = Path(_HOME.name) / "rs274ngc.var"
"""rs274's parameter file (``-v``), removed before each run: every run starts from the
default parameters, as ``parse`` does. Left to itself rs274 reads and rewrites the
``rs274ngc.var`` of its working folder: LinuxCNC's example folders ship one, so their
programs would start from the offsets the previous program there left (and the package's
files would be rewritten)."""
CANON = Path(__file__).with_name("linuxcnc_canon.py")

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
    feed_call: int = -1             # which SET_FEED_RATE call set the feed (0, 1, ...)
    feed_unit: float = MM           # the unit the feed was given in (per minute)


@dataclass
class Reference:
    moves: list[CanonMove]
    error: str | None               # rs274's message when it stopped on an error
    error_block: str | None         # the block it stopped at
    other_axes: bool = False        # a move of A, B, C (U, V, W), or a probe
    precise: bool = False           # ends, centres and feeds are the binding's doubles
    feed_calls: int = 0             # how many SET_FEED_RATE calls rs274 printed


def _numbers(args: str) -> list[float]:
    return [float(part) for part in (p.strip() for p in args.split(","))
            if re.fullmatch(r"[-+]?[0-9]*\.?[0-9]+", part)]


def run_rs274(path: Path) -> Reference:
    """Run LinuxCNC's interpreter on ``path``; its moves in SI machine coordinates."""
    for stale in (_VARS, _VARS.with_name(_VARS.name + ".bak")):
        stale.unlink(missing_ok=True)
    done = subprocess.run([RS274, "-v", str(_VARS), "-g", str(path)], capture_output=True,
                          text=True, timeout=60, stdin=subprocess.DEVNULL, cwd=path.parent,
                          errors="replace", env=ENV)
    other = False
    unit, feed = MM, None
    feed_call, feed_unit = -1, MM
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
            feed_call, feed_unit = feed_call + 1, unit
        elif name == "SET_G5X_OFFSET":
            g5x = (values[1] * unit, values[2] * unit)
        elif name == "SET_G92_OFFSET":
            g92 = (values[0] * unit, values[1] * unit)
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED"):
            feeding = dict(feed_call=feed_call, feed_unit=feed_unit)
            end = (values[0] * unit + g5x[0] + g92[0], values[1] * unit + g5x[1] + g92[1])
            if name == "ARC_FEED":
                center = (values[2] * unit + g5x[0] + g92[0],
                          values[3] * unit + g5x[1] + g92[1])
                rotation = int(values[4])
                moves.append(CanonMove("arc", end, feed, center, rotation > 0,
                                       abs(rotation) - 1, unit, **feeding))
            else:
                if end == position:
                    continue                       # a Z-only move: no XY motion
                moves.append(CanonMove("rapid" if name == "STRAIGHT_TRAVERSE" else "line",
                                       end, None if name == "STRAIGHT_TRAVERSE" else feed,
                                       unit=unit, unsure=math.isnan(position[0]),
                                       **feeding))
            position = end
    error = block = None
    if done.returncode != 0:
        said = [row.strip() for row in done.stderr.splitlines()
                if row.strip() and row.strip() != "executing"]
        error = said[0] if said else f"rs274 exited {done.returncode}"
        block = said[-1] if len(said) > 1 else ""
    reference = Reference(moves, error, block, other, feed_calls=feed_call + 1)
    if BINDING is not None and error is None and not other:
        _make_precise(reference, path)
    return reference


def _make_precise(reference: Reference, path: Path) -> None:
    """Put the binding's full-precision ends, centres and feeds in place of rs274's printed
    ones (a feed is given in the program unit of its SET_FEED_RATE, which rs274 prints).

    Both are the same interpreter on the same file, so the moves must pair one to one;
    a program with a spline keeps the printed values (the binding, like rs274, gives no
    spline end, and the Z-only moves after it cannot be told apart). Only programs rs274
    runs to the end are made precise: what a refused one moved is not compared. The
    binding run without a machine configuration crashes on a tool number (T, M6, M61): such
    a program keeps the printed values too."""
    if any(move.kind == "spline" for move in reference.moves):
        return
    done = subprocess.run([BINDING, str(CANON), str(path.resolve())], capture_output=True,
                          text=True, timeout=60, stdin=subprocess.DEVNULL, cwd=path.parent,
                          env=ENV)
    rows = [json.loads(row) for row in done.stdout.splitlines() if row.startswith("[")]
    if done.returncode != 0 or not rows or rows[-1][0] != "end":
        return
    moves = [row for row in rows if row[0] in ("rapid", "line", "arc")]
    assert [row[0] for row in moves] == [move.kind for move in reference.moves], \
        f"LinuxCNC's binding and rs274 disagree on the moves of {path}: {done.stderr[-500:]}"
    for move, (_, x, y, cx, cy, rotation) in zip(reference.moves, moves, strict=True):
        printed = move.end
        move.end = (x * INCH, y * INCH)
        assert math.dist(printed, move.end) <= math.sqrt(2) * (PRINTED * move.unit + 1e-9), \
            (path, printed, move.end)
        if move.kind == "arc":
            move.center = (cx * INCH, cy * INCH)
            assert (move.ccw, move.turns) == (rotation > 0, abs(rotation) - 1)
    feeds = [row[1] for row in rows if row[0] == "feed"]
    assert len(feeds) == reference.feed_calls, (path, feeds)
    for move in reference.moves:
        if move.feed is not None:
            # the binding divides a feed by 25.4 when its own metric flag is set, which
            # follows USE_LENGTH_UNITS rather than the unit the feed was given in: the
            # printed value (4 decimals) tells which of the two readings it is
            printed, given = move.feed, feeds[move.feed_call]
            move.feed = min((given * INCH / 60.0, given * move.feed_unit / 60.0),
                            key=lambda feed: abs(feed - printed))
            assert abs(printed - move.feed) <= PRINTED * move.feed_unit / 60.0 + 1e-12
    reference.precise = True
