"""A realistic nest of sheet-metal parts as G-code, for seed 001's laser-cutting job.

Seed 001 gives only the totals of its industrial job: 32 471.6 mm of cut, 5 304.6 mm of idle
travel, on a 1.25 × 0.8 m table. This module generates a job of that kind: a grid of parts
of five typical shapes, each cut the way a nesting CAM cuts it (inner contours first, then
the outline; a laser-on/off M3/M5 around each contour; rapids between contours):

* ``flange`` — a circle with a centre hole and a bolt circle of holes (G2/G3 arcs);
* ``bracket`` — a rectangle with rounded corners (lines and tangent 90° arcs) and two holes;
* ``sprocket`` — a toothed wheel: a polygon of short lines with sharp corners;
* ``cam`` — a free-form outline exported as a spline *polyline*: chords within a chordal
  tolerance of 0.02 mm, so many short lines meeting at small angles (what CAM systems of
  the seed's time sent to the controller);
* ``comb`` — a heat-sink plate with fins: one long outline of right angles.

``nest(chord=0.01)`` writes every arc and circle as chords within that chordal tolerance
instead, as a CAM post-processor without G2/G3 output does: thousands of short lines meeting
at small angles (the planner's hardest input; issue 12).

The grid sets the totals. The default, 6 × 4 parts on 1020 × 720 mm, gives 32.6 m of cut
(seed: 32.5 m) and 6.6 m of rapid travel (seed: 5.3 m; the seed's parts were not published,
and holes cost rapid travel: ours have 98 contours); a smaller grid gives a short job for
tests. Coordinates are absolute millimetres from the table origin; the program starts and
ends at the home position (10, 10) mm.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

__all__ = ["KINDS", "Nest", "Part", "chord_length", "layout", "nest", "random_nest"]

_FEED = 3000.0            # mm/min: 50 mm/s, seed 001's max cutting speed
_CHORD_TOL = 0.02         # mm: chordal tolerance of the exported spline polylines
KINDS = ("flange", "bracket", "sprocket", "cam", "comb")
"""The part shapes a nest is made of."""
_KINDS = KINDS


@dataclass(frozen=True)
class Part:
    """One part of a nest: its ``kind`` (one of ``KINDS``), its cell's lower left corner
    ``x``, ``y`` and size ``width`` × ``height`` (mm), and ``size`` 0 … 1 within the cell's
    room for that kind."""

    kind: str
    x: float
    y: float
    width: float
    height: float
    size: float


@dataclass
class Nest:
    """A generated job.

    Attributes
    ----------
    gcode : str
        The program (mm, absolute).
    cut_length, idle_length : float
        Length of the cutting moves and of the rapids (mm).
    contours, parts : int
        Number of cut contours and of parts.
    blocks : int
        Motion blocks (G1/G2/G3 and G0).
    """

    gcode: str = ""
    cut_length: float = 0.0
    idle_length: float = 0.0
    contours: int = 0
    parts: int = 0
    blocks: int = 0
    part_lines: list[tuple[int, int]] = field(default_factory=list)
    """Per part cut, its first and last line of ``gcode`` (1-based)."""
    _lines: list[str] = field(default_factory=list, repr=False)
    _here: tuple[float, float] = (10.0, 10.0)
    _chord: float | None = None

    # -- writers -----------------------------------------------------------------------
    def _rapid(self, x: float, y: float) -> None:
        self.idle_length += math.dist(self._here, (x, y))
        self._lines.append(f"G0 X{x:.3f} Y{y:.3f}")
        self._here = (x, y)
        self.blocks += 1

    def _line(self, x: float, y: float) -> None:
        self.cut_length += math.dist(self._here, (x, y))
        self._lines.append(f"G1 X{x:.3f} Y{y:.3f}")
        self._here = (x, y)
        self.blocks += 1

    def _chords(self, cx: float, cy: float, r: float, a0: float, sweep: float) -> None:
        """The arc from angle ``a0`` over ``sweep`` (rad, signed) as chords within the
        chordal tolerance, ending exactly on its end point."""
        n = max(1, math.ceil(abs(sweep) * r / chord_length(r, self._chord)))
        for k in range(1, n + 1):
            a = a0 + sweep * k / n
            self._line(cx + r * math.cos(a), cy + r * math.sin(a))

    def _circle(self, cx: float, cy: float, r: float) -> None:
        """A full circle, counter-clockwise, pierced at the point nearest to the head."""
        a = math.atan2(self._here[1] - cy, self._here[0] - cx)
        x, y = cx + r * math.cos(a), cy + r * math.sin(a)
        self._contour([(x, y)])
        if self._chord is not None:
            self._chords(cx, cy, r, a, 2.0 * math.pi)
            self._lines.append("M5")
            return
        self.cut_length += 2.0 * math.pi * r
        self._lines.append(f"G3 X{x:.3f} Y{y:.3f} I{cx - x:.3f} J{cy - y:.3f}")
        self.blocks += 1
        self._lines.append("M5")

    def _arc(self, x: float, y: float, cx: float, cy: float, *, ccw: bool = True) -> None:
        """An arc to (x, y) about (cx, cy) of at most a half turn."""
        r = math.dist((cx, cy), (x, y))
        a0 = math.atan2(self._here[1] - cy, self._here[0] - cx)
        a1 = math.atan2(y - cy, x - cx)
        sweep = (a1 - a0) % (2.0 * math.pi) if ccw else (a0 - a1) % (2.0 * math.pi)
        if self._chord is not None:
            self._chords(cx, cy, r, a0, sweep if ccw else -sweep)
            return
        self.cut_length += r * sweep
        i, j = cx - self._here[0], cy - self._here[1]
        self._lines.append(f"{'G3' if ccw else 'G2'} X{x:.3f} Y{y:.3f} I{i:.3f} J{j:.3f}")
        self._here = (x, y)
        self.blocks += 1

    def _contour(self, start: list[tuple[float, float]]) -> None:
        """Rapid to the contour's start and switch the beam on."""
        self._rapid(*start[0])
        self._lines.append("M3")
        self.contours += 1

    def _polygon(self, points: list[tuple[float, float]]) -> None:
        """A closed polyline, pierced at the vertex nearest to the head."""
        k = min(range(len(points)), key=lambda i: math.dist(points[i], self._here))
        points = points[k:] + points[:k]
        self._contour(points)
        for x, y in points[1:] + points[:1]:
            self._line(x, y)
        self._lines.append("M5")

    def _part(self, inner: list[tuple[float, float, float]],
              outline: Callable[[], None] | None) -> None:
        """Cut the holes ``(cx, cy, r)`` nearest first (as a CAM orders them), then the
        outline."""
        todo = list(inner)
        while todo:
            k = min(range(len(todo)), key=lambda i: math.dist(todo[i][:2], self._here))
            self._circle(*todo.pop(k))
        if outline is not None:
            outline()
        self.parts += 1

    # -- parts (cell origin x0, y0; cell size w × h; s ∈ [0, 1) varies the size) -------
    def flange(self, x0: float, y0: float, w: float, h: float, s: float) -> None:
        cx, cy = x0 + w / 2, y0 + h / 2
        r = (0.36 + 0.08 * s) * min(w, h)
        holes = [(cx, cy, 0.22 * r)]
        for n, rb, rh in ((6 + 2 * int(2 * s), 0.7 * r, 0.07 * r),):
            holes += [(cx + rb * math.cos(2.0 * math.pi * k / n),
                       cy + rb * math.sin(2.0 * math.pi * k / n), rh) for k in range(n)]
        self._part(holes, lambda: self._circle(cx, cy, r))

    def bracket(self, x0: float, y0: float, w: float, h: float, s: float) -> None:
        bw, bh, rc = (0.8 + 0.1 * s) * w, (0.55 + 0.3 * s) * h, 0.12 * min(w, h)
        x1, y1 = x0 + (w - bw) / 2, y0 + (h - bh) / 2
        x2, y2 = x1 + bw, y1 + bh

        def outline() -> None:
            self._contour([(x1 + rc, y1)])
            self._line(x2 - rc, y1)
            self._arc(x2, y1 + rc, x2 - rc, y1 + rc)
            self._line(x2, y2 - rc)
            self._arc(x2 - rc, y2, x2 - rc, y2 - rc)
            self._line(x1 + rc, y2)
            self._arc(x1, y2 - rc, x1 + rc, y2 - rc)
            self._line(x1, y1 + rc)
            self._arc(x1 + rc, y1, x1 + rc, y1 + rc)
            self._lines.append("M5")

        self._part([(x1 + (0.15 + 0.233 * i) * bw, y1 + 0.5 * bh, 0.07 * bh)
                    for i in range(4)], outline)

    def sprocket(self, x0: float, y0: float, w: float, h: float, s: float) -> None:
        cx, cy = x0 + w / 2, y0 + h / 2
        r_out = 0.44 * min(w, h)
        r_in = 0.7 * r_out
        teeth = 24 + int(12 * s)
        pts = []
        for k in range(teeth):
            a = 2.0 * math.pi * k / teeth
            da = math.pi / teeth
            for ang, r in ((a - 0.45 * da, r_in), (a - 0.2 * da, r_out), (a + 0.2 * da, r_out),
                           (a + 0.45 * da, r_in)):
                pts.append((cx + r * math.cos(ang), cy + r * math.sin(ang)))
        self._part([(cx, cy, 0.2 * r_out)], lambda: self._polygon(pts))

    def cam(self, x0: float, y0: float, w: float, h: float, s: float) -> None:
        cx, cy = x0 + w / 2, y0 + h / 2
        a, b = 0.45 * w, (0.3 + 0.1 * s) * h
        pts = list(_cam_outline(cx, cy, a, b))
        self._part([(cx - 0.2 * a, cy, 0.15 * b), (cx + 0.3 * a, cy, 0.1 * b),
                    (cx + 0.55 * a, cy, 0.06 * b)], lambda: self._polygon(pts))

    def comb(self, x0: float, y0: float, w: float, h: float, s: float) -> None:
        """A heat-sink plate: a base with fins, one outline of many right angles."""
        fins = 8 + int(6 * s)
        xa, xb = x0 + 0.06 * w, x0 + 0.94 * w
        yb, yt = y0 + 0.08 * h, y0 + 0.92 * h
        base = yb + 0.22 * (yt - yb)
        pitch = (xb - xa) / fins
        pts = [(xa, yb), (xb, yb)]
        for k in range(fins - 1, -1, -1):      # fins from right to left along the top
            left, right = xa + k * pitch, xa + (k + 0.55) * pitch
            pts += [(xa + (k + 1) * pitch, base) if k < fins - 1 else (xb, base),
                    (right, base), (right, yt), (left, yt)]
        pts = [p for i, p in enumerate(pts) if i == 0 or math.dist(p, pts[i - 1]) > 1e-6]
        self._part([], lambda: self._polygon(pts))


def _cam_outline(cx: float, cy: float, a: float, b: float) -> Iterator[tuple[float, float]]:
    """A free-form closed outline (an egg-shaped cam) as chords within ``_CHORD_TOL``."""
    def point(t: float) -> tuple[float, float]:
        r = 1.0 + 0.18 * math.cos(t) + 0.06 * math.cos(3.0 * t)
        return cx + a * r * math.cos(t) / 1.24, cy + b * r * math.sin(t) / 1.24

    t = 0.0
    while t < 2.0 * math.pi - 1e-9:
        yield point(t)
        # chord length for the tolerance on the local radius of curvature (≥ b/2 here)
        rho = max(0.5 * min(a, b), 1.0)
        t += math.sqrt(8.0 * rho * _CHORD_TOL) / max(a, b)


def chord_length(radius: float, tolerance: float) -> float:
    """Longest chord of a circle of ``radius`` whose sagitta is within ``tolerance`` (mm)."""
    tolerance = min(tolerance, radius)
    return 2.0 * math.sqrt(tolerance * (2.0 * radius - tolerance))


def nest(cols: int = 6, rows: int = 4, *, width: float = 1020.0, height: float = 720.0,
         origin: tuple[float, float] = (12.0, 12.0), chord: float | None = None) -> Nest:
    """A grid of ``cols × rows`` parts on the sheet, cut row by row (serpentine).

    Parameters
    ----------
    cols, rows : int
        Parts per row and rows.
    width, height : float
        Area of the nest (mm); the cells share it.
    origin : (float, float)
        Lower left corner of the nest (mm).
    chord : float, optional
        Chordal tolerance (mm): write arcs and circles as G1 chords within it, as a CAM
        post-processor without arc output does; None (default) writes G2/G3.

    Returns
    -------
    Nest
        The program and its totals.
    """
    if cols < 1 or rows < 1:
        raise ValueError(f"cols and rows must be >= 1, got {cols} × {rows}")
    w, h = width / cols, height / rows
    parts = []
    for row in range(rows):
        order = range(cols) if row % 2 == 0 else range(cols - 1, -1, -1)
        for col in order:
            k = row * cols + col
            parts.append(Part(_KINDS[(col + 2 * row) % len(_KINDS)], origin[0] + col * w,
                              origin[1] + row * h, w, h, ((7 * k) % 10) / 10.0))
    return layout(parts, title=f"xy-twin nest: {cols} x {rows} parts, laser_belt",
                  chord=chord)


def layout(parts: list[Part], *, title: str = "xy-twin nest", chord: float | None = None
           ) -> Nest:
    """The program that cuts ``parts`` in their order, from and back to the home position
    (10, 10) mm; ``chord`` as in ``nest``.

    Raises
    ------
    ValueError
        An unknown kind, or a chordal tolerance that is not positive.
    """
    if chord is not None and not chord > 0.0:
        raise ValueError(f"chord must be > 0 mm, got {chord!r}")
    job = Nest(_chord=chord)
    job._lines = ["%", f"({title})", "G21 G90 G17 G94", f"F{_FEED:g}"]
    for part in parts:
        if part.kind not in KINDS:
            raise ValueError(f"unknown part kind {part.kind!r}; valid: {', '.join(KINDS)}")
        first = len(job._lines) + 1
        getattr(job, part.kind)(part.x, part.y, part.width, part.height, part.size)
        job.part_lines.append((first, len(job._lines)))
    job._rapid(10.0, 10.0)
    job._lines += ["M30", "%"]
    job.gcode = "\n".join(job._lines) + "\n"
    return job


def random_nest(seed: int, *, chord: float | None = None) -> tuple[Nest, list[Part]]:
    """A nest of seed 001's class with random parameters: a grid of 2–4 × 1–3 cells of
    80–220 mm, each a part of a random kind and size, its corner 12–100 mm from the
    origin, cut row by row (serpentine). Returns the program and its parts."""
    import numpy as np

    rng = np.random.default_rng(seed)
    cols, rows = int(rng.integers(2, 5)), int(rng.integers(1, 4))
    w, h = float(rng.uniform(80.0, 220.0)), float(rng.uniform(80.0, 220.0))
    origin = (float(rng.uniform(12.0, 100.0)), float(rng.uniform(12.0, 100.0)))
    parts = []
    for row in range(rows):
        order = range(cols) if row % 2 == 0 else range(cols - 1, -1, -1)
        for col in order:
            kind = str(rng.choice(KINDS))
            parts.append(Part(kind, origin[0] + col * w, origin[1] + row * h, w, h,
                              float(rng.uniform(0.0, 1.0))))
    return layout(parts, title=f"random nest seed {seed}", chord=chord), parts
