"""CAM-like programs: what post-processors send a two-axis machine, for the planner's bench.

Real jobs reach a controller as thousands of short chords, not as G2/G3 arcs (issue 12).
This module writes such programs, in absolute millimetres, with a laser-style M3/M5 around
every contour and rapids between contours:

* ``chorded_nest`` — seed 001's nest of sheet-metal parts (`twin.analysis.studies.nest`) with every
  arc and circle written as chords within a chordal tolerance;
* ``lettering`` — the outlines of a line of text (DejaVu Sans through matplotlib's
  ``TextPath``): the glyphs' quadratic Bézier curves flattened into chords within the
  tolerance, sharp corners where strokes meet;
* ``pocket`` — a rectangular pocket cleared by a zig-zag raster (long passes, short
  step-overs, right-angle turns) and finished by one contour pass with rounded corners;
* ``circle`` — one circle, as G2/G3 or as chords of a given length (the chord-independence
  check);
* ``chords`` — one long free-form curve as a given number of chords (the throughput check).

And what the bench and the tests measure on their plans: ``planned_time`` (the cycle time
of a plan), ``middle_speed`` (the planned speed halfway along the feed moves),
``sampled_reference`` (the position reference period by period), ``sampled_extremes`` and
``sampled_acceleration`` (the acceleration and jerk of that reference as the axes receive
it). The random program classes of issue 30 are in
`twin.analysis.studies.cam_classes`.

Coordinates are written with ``decimals`` places (3 by default, as CAM posts round them); a
chord shorter than that resolution is not representable, so ``circle`` takes more.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from twin.analysis.studies.nest import chord_length, nest
from twin.controller.blocks import PlannedBlock
from twin.controller.interpolator import Interpolator, InterpolatorStatus

__all__ = ["Writer", "chorded_nest", "chords", "circle", "glyph_contours", "lettering",
           "middle_speed", "nearest_first", "planned_time", "pocket", "sampled_acceleration",
           "sampled_extremes", "sampled_reference"]

_HEADER = "G21 G90 G17 G94"


class Writer:
    """G-code text of contours: rapids between them, M3/M5 around each."""

    def __init__(self, feed: float, decimals: int, title: str):
        self.feed, self.decimals = feed, decimals
        self.lines = ["%", f"({title})", _HEADER, f"F{feed:g}"]

    def xy(self, x: float, y: float) -> str:
        d = self.decimals
        return f"X{x:.{d}f} Y{y:.{d}f}"

    def contour(self, points: Sequence[tuple[float, float]]) -> None:
        """A polyline cut from its first point: rapid there, beam on, G1 through the rest."""
        self.lines.append(f"G0 {self.xy(*points[0])}")
        self.lines.append("M3")
        last = self.xy(*points[0])
        for p in points[1:]:
            word = self.xy(*p)
            if word != last:                 # a chord shorter than the resolution
                self.lines.append(f"G1 {word}")
                last = word
        self.lines.append("M5")

    def text(self, home: tuple[float, float]) -> str:
        self.lines += [f"G0 {self.xy(*home)}", "M30", "%"]
        return "\n".join(self.lines) + "\n"


def chorded_nest(cols: int = 6, rows: int = 4, *, chord: float = 0.01) -> str:
    """Seed 001's nest (32.6 m of cut for 6 × 4 parts) with arcs as chords within ``chord``
    (mm)."""
    return nest(cols, rows, chord=chord).gcode


def _quad(p0: Sequence[float], p1: Sequence[float], p2: Sequence[float],
          tolerance: float) -> list[tuple[float, float]]:
    """A quadratic Bézier as chords within ``tolerance``: its second derivative is the
    constant 2·(p0 − 2·p1 + p2), so n equal parameter steps deviate by at most
    |p0 − 2·p1 + p2| / (4·n²)."""
    bx, by = p0[0] - 2.0 * p1[0] + p2[0], p0[1] - 2.0 * p1[1] + p2[1]
    n = max(1, math.ceil(math.sqrt(math.hypot(bx, by) / (4.0 * tolerance))))
    out = []
    for k in range(1, n + 1):
        t = k / n
        u = 1.0 - t
        out.append((u * u * p0[0] + 2.0 * u * t * p1[0] + t * t * p2[0],
                    u * u * p0[1] + 2.0 * u * t * p1[1] + t * t * p2[1]))
    return out


def glyph_contours(text: str, height: float, chord: float
                    ) -> list[list[tuple[float, float]]]:
    """The closed outlines of ``text`` (cap height about ``height`` mm) as chord polylines."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.path import Path
    from matplotlib.textpath import TextPath

    path = TextPath((0.0, 0.0), text, size=height / 0.73,     # DejaVu's cap height 0.73 em
                    prop=FontProperties(family="DejaVu Sans"))
    contours: list[list[tuple[float, float]]] = []
    current: list[tuple[float, float]] = []
    verts, codes = path.vertices, path.codes
    i = 0
    while i < len(codes):
        code = codes[i]
        if code == Path.MOVETO:
            if len(current) > 1:
                contours.append(current)
            current = [tuple(verts[i])]
            i += 1
        elif code == Path.LINETO:
            current.append(tuple(verts[i]))
            i += 1
        elif code == Path.CURVE3:
            current += _quad(current[-1], verts[i], verts[i + 1], chord)
            i += 2
        elif code == Path.CURVE4:           # not in TrueType fonts; flattened finely
            p0, p1, p2, p3 = current[-1], verts[i], verts[i + 1], verts[i + 2]
            n = 64
            current += [tuple((1 - t) ** 3 * p0[k] + 3 * (1 - t) ** 2 * t * p1[k]
                              + 3 * (1 - t) * t * t * p2[k] + t ** 3 * p3[k] for k in (0, 1))
                        for t in (j / n for j in range(1, n + 1))]
            i += 3
        else:                                 # CLOSEPOLY
            if current and current[-1] != current[0]:
                current.append(current[0])
            i += 1
    if len(current) > 1:
        contours.append(current)
    return contours


def lettering(text: str = "XY-twin 2026", *, height: float = 40.0, chord: float = 0.01,
              origin: tuple[float, float] = (50.0, 50.0), feed: float = 3000.0,
              decimals: int = 3) -> str:
    """Engrave the outlines of ``text``: capitals ``height`` mm tall, curves as chords
    within ``chord`` mm, at ``feed`` mm/min; contours cut nearest first."""
    w = Writer(feed, decimals, f"xy-twin lettering: {text!r}, {height:g} mm, chord {chord:g}")
    contours = [[(origin[0] + x, origin[1] + y) for x, y in c]
                for c in glyph_contours(text, height, chord)]
    for c in nearest_first(contours, origin):
        w.contour(c)
    return w.text((origin[0] - 40.0, origin[1] - 40.0))


def nearest_first(contours: list[list[tuple[float, float]]], here: tuple[float, float]
                   ) -> Iterable[list[tuple[float, float]]]:
    todo = list(contours)
    while todo:
        k = min(range(len(todo)), key=lambda i: math.dist(todo[i][0], here))
        c = todo.pop(k)
        here = c[-1]
        yield c


def pocket(width: float = 120.0, height: float = 80.0, *, tool: float = 6.0,
           stepover: float = 0.6, corner: float = 8.0, chord: float = 0.01,
           origin: tuple[float, float] = (300.0, 200.0), feed: float = 3000.0,
           decimals: int = 3) -> str:
    """Clear a ``width`` × ``height`` mm pocket with a ``tool`` mm cutter: a zig-zag raster
    along x at ``stepover`` × the tool diameter, then one finishing pass around the wall
    with corners of radius ``corner`` mm, as chords within ``chord`` mm."""
    w = Writer(feed, decimals, f"xy-twin pocket {width:g} x {height:g} mm, tool {tool:g}")
    r = tool / 2.0
    x0, y0 = origin[0] + r, origin[1] + r
    x1, y1 = origin[0] + width - r, origin[1] + height - r
    step = stepover * tool
    rows = max(1, math.ceil((y1 - y0) / step))
    zig = []
    for k in range(rows + 1):
        y = y0 + (y1 - y0) * k / rows
        xs = (x0 + r, x1 - r) if k % 2 == 0 else (x1 - r, x0 + r)
        zig += [(xs[0], y), (xs[1], y)]
    w.contour(zig)
    rc = max(corner - r, 0.0)
    wall = [(x0 + rc, y0), (x1 - rc, y0)]
    for cx, cy, a0 in ((x1 - rc, y0 + rc, -0.5 * math.pi), (x1 - rc, y1 - rc, 0.0),
                       (x0 + rc, y1 - rc, 0.5 * math.pi), (x0 + rc, y0 + rc, math.pi)):
        if rc > 0.0:
            n = max(1, math.ceil(0.5 * math.pi * rc / chord_length(rc, chord)))
            wall += [(cx + rc * math.cos(a0 + 0.5 * math.pi * k / n),
                      cy + rc * math.sin(a0 + 0.5 * math.pi * k / n)) for k in range(1, n + 1)]
        nxt = {-0.5 * math.pi: (x1, y1 - rc), 0.0: (x0 + rc, y1),
               0.5 * math.pi: (x0, y0 + rc), math.pi: (x0 + rc, y0)}[a0]
        wall.append(nxt)
    w.contour(wall)
    return w.text((origin[0] - 20.0, origin[1] - 20.0))


def circle(radius: float, *, chord: float | None = None, center: tuple[float, float] = (
           200.0, 200.0), feed: float = 3000.0, decimals: int = 9) -> str:
    """One full counter-clockwise circle of ``radius`` mm: a G3 arc (``chord`` None), or
    chords of at most ``chord`` mm."""
    w = Writer(feed, decimals, f"xy-twin circle r {radius:g} mm, "
                                f"{'G3' if chord is None else f'chords {chord:g} mm'}")
    cx, cy = center
    start = (cx + radius, cy)
    if chord is None:
        w.lines += [f"G0 {w.xy(*start)}", "M3", f"G3 {w.xy(*start)} I{-radius:.{decimals}f} J0",
                    "M5"]
    else:
        n = max(3, math.ceil(2.0 * math.pi * radius / chord))
        w.contour([(cx + radius * math.cos(2.0 * math.pi * k / n),
                    cy + radius * math.sin(2.0 * math.pi * k / n)) for k in range(n + 1)])
    return w.text((cx - radius - 10.0, cy - radius - 10.0))


def chords(blocks: int, *, chord: float = 0.005, center: tuple[float, float] = (400.0, 300.0),
           size: float = 250.0, feed: float = 3000.0, decimals: int = 4) -> str:
    """One contour of ``blocks`` chords along a Lissajous curve (3:4, ``size`` mm across),
    each chord as long as the chordal tolerance ``chord`` (mm) allows at the local radius
    of curvature, so the chords run from tenths of a millimetre in the tight bends to a few
    millimetres on the flanks; the curve is followed round again until the count is reached.
    """
    w = Writer(feed, decimals, f"xy-twin chords: {blocks} along a Lissajous curve")
    half = 0.5 * size

    def point(t: float) -> tuple[float, float]:
        return (center[0] + half * math.sin(3.0 * t + 0.5), center[1] + half * math.sin(4.0 * t))

    def radius(t: float) -> float:
        dx, dy = 3.0 * half * math.cos(3.0 * t + 0.5), 4.0 * half * math.cos(4.0 * t)
        ddx, ddy = -9.0 * half * math.sin(3.0 * t + 0.5), -16.0 * half * math.sin(4.0 * t)
        speed = math.hypot(dx, dy)
        return speed**3 / max(abs(dx * ddy - dy * ddx), 1e-12)

    pts = [point(0.0)]
    t = 0.0
    while len(pts) <= blocks:
        speed = math.hypot(3.0 * half * math.cos(3.0 * t + 0.5), 4.0 * half * math.cos(4.0 * t))
        t += chord_length(radius(t), chord) / max(speed, 1e-9)
        pts.append(point(t))
    w.contour(pts)
    return w.text((10.0, 10.0))


def planned_time(items: Iterable[Any], feed_only: bool = False) -> float:
    """A plan's cycle time (s): its blocks' profile durations (a run's one move counted
    once) and its dwells; ``feed_only``: the feed moves alone."""
    total = 0.0
    run = None                       # the run being counted: its members are consecutive
    for it in items:
        if isinstance(it, PlannedBlock):
            if feed_only and it.rapid:
                continue
            piece = it.piece
            if piece is None:
                total += it.profile().duration
            elif piece[0] is not run:
                run = piece[0]
                total += run.duration
        elif hasattr(it, "duration") and not feed_only:
            total += it.duration
    return total


def middle_speed(items: Iterable[Any]) -> float:
    """The highest planned path speed (m/s) on the block halfway along the feed moves of a
    plan (the cruise of a circle program, say)."""
    blocks = [b for b in items if isinstance(b, PlannedBlock) and not b.rapid]
    half = 0.5 * sum(b.segment.length for b in blocks)
    s = 0.0
    for b in blocks:
        if s + b.segment.length >= half:
            prof = b.profile()
            return float(np.max(prof.sample(np.linspace(0.0, prof.duration, 201))[1]))
        s += b.segment.length
    raise ValueError("the plan has no feed move")


def sampled_reference(items: Iterable[Any], period: float) -> np.ndarray:
    """A plan's position reference (m, shape (n, 2)) as the interpolator samples it every
    ``period``, from the start point to the end point at rest."""
    interp = Interpolator([i for i in items if isinstance(i, PlannedBlock)
                           or hasattr(i, "duration")], period=period)
    pos = [interp.reference.position.copy()]
    while interp.update() < InterpolatorStatus.FINISHED:
        pos.append(interp.reference.position.copy())
    pos.append(interp.reference.position.copy())
    return np.array(pos)


def sampled_acceleration(items: Iterable[Any], period: float) -> np.ndarray:
    """Largest |Δ²p|/T² per axis (m/s², shape (2,)) of a plan's position reference sampled
    every ``period`` by the interpolator: a velocity step at a node counts as Δv/T, as the
    axes receive it."""
    return sampled_extremes(sampled_reference(items, period), period)[0]


def sampled_extremes(pos: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Largest |Δ²p|/T² (m/s²) and |Δ³p|/T³ (m/s³) per axis (each shape (2,)) of a sampled
    position reference ``pos`` (m, shape (n, 2)): the acceleration and the jerk the axes
    receive, a step of acceleration within one period counting as its jump over T."""
    d2 = np.diff(pos, 2, axis=0)
    return (np.abs(d2).max(axis=0) / period**2,
            np.abs(np.diff(d2, axis=0)).max(axis=0) / period**3)
