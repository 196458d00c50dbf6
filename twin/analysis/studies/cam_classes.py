"""Random CAM program classes where a planner is easily slow: each a seeded generator, so
a bench or a test draws as many varied instances as it likes (issue 30).

* ``small_text`` — engraved lines of random text, capitals 2–5 mm tall, outlines chorded
  within 0.003–0.01 mm: many short contours of short chords, corners of every angle;
* ``small_radii`` — free-form contours of tangent arcs of radius 0.5–5 mm (random sweeps
  and turning directions, short lines between some) and small holes, chorded within
  0.005–0.01 mm: densely chorded tight curves;
* ``flattened_3d`` — a 3-axis raster finishing path over a random smooth surface, written
  as its XY projection: long runs of nearly collinear chords whose lengths follow the
  surface's slope and whose directions wobble by a few micrometres (the post's rounding
  of a 3-D path, the CAM's own chordal noise).

Every generator takes a ``numpy.random.Generator`` and returns ``(gcode, params)``: the
program (absolute mm) and the parameters it drew, for the record. ``CLASSES`` maps the
class names to them.
"""

from __future__ import annotations

import math
import string
from collections.abc import Callable

import numpy as np

from twin.analysis.studies.cam import Writer, glyph_contours, nearest_first
from twin.analysis.studies.nest import chord_length

__all__ = ["CLASSES", "flattened_3d", "small_radii", "small_text"]

Generated = tuple[str, dict]


def _feed(rng: np.random.Generator) -> float:
    """A cutting feed (mm/min): 1800–3000, the top of laser_belt's contour speed."""
    return float(np.round(rng.uniform(1800.0, 3000.0), -1))


def small_text(rng: np.random.Generator) -> Generated:
    """One to three lines of random words, capitals 2–5 mm tall (see the module doc)."""
    height = float(rng.uniform(2.0, 5.0))
    chord = float(rng.uniform(0.003, 0.01))
    feed = _feed(rng)
    alphabet = string.ascii_letters + string.digits
    lines = []
    for _ in range(int(rng.integers(1, 4))):
        words = ["".join(rng.choice(list(alphabet), size=int(rng.integers(2, 8))))
                 for _ in range(int(rng.integers(1, 4)))]
        lines.append(" ".join(words))
    origin = (float(rng.uniform(40.0, 400.0)), float(rng.uniform(40.0, 300.0)))
    w = Writer(feed, 3, f"xy-twin small text, {height:.2f} mm, chord {chord:.4f} mm")
    contours = []
    for k, text in enumerate(lines):
        y0 = origin[1] - 1.6 * height * k
        contours += [[(origin[0] + x, y0 + y) for x, y in c]
                     for c in glyph_contours(text, height, chord)]
    for c in nearest_first(contours, origin):
        w.contour(c)
    params = {"lines": lines, "height_mm": round(height, 3), "chord_mm": round(chord, 4),
              "feed_mm_per_min": feed}
    return w.text((origin[0] - 20.0, origin[1] - 20.0)), params


def _arc_points(cx: float, cy: float, r: float, a0: float, sweep: float,
                tolerance: float) -> list[tuple[float, float]]:
    """The arc from angle ``a0`` over ``sweep`` (rad, signed) as chords within
    ``tolerance`` (mm), without its start point."""
    n = max(1, math.ceil(abs(sweep) * r / chord_length(r, tolerance)))
    return [(cx + r * math.cos(a0 + sweep * k / n), cy + r * math.sin(a0 + sweep * k / n))
            for k in range(1, n + 1)]


def small_radii(rng: np.random.Generator) -> Generated:
    """Free-form contours of tangent arcs of radius 0.5–5 mm and small holes (module doc)."""
    tolerance = float(rng.uniform(0.005, 0.01))
    feed = _feed(rng)
    w = Writer(feed, 4, f"xy-twin small radii, chord tolerance {tolerance:.4f} mm")
    contours = []
    base = np.array([rng.uniform(50.0, 300.0), rng.uniform(50.0, 300.0)])
    for c in range(int(rng.integers(3, 7))):
        x, y = base + c * np.array([35.0, 0.0])
        heading = float(rng.uniform(0.0, 2.0 * math.pi))
        pts = [(float(x), float(y))]
        for _ in range(int(rng.integers(6, 16))):
            if rng.random() < 0.25:                      # a short straight between arcs
                length = float(rng.uniform(0.2, 3.0))
                x, y = x + length * math.cos(heading), y + length * math.sin(heading)
                pts.append((x, y))
            r = float(np.exp(rng.uniform(math.log(0.5), math.log(5.0))))
            turn = 1.0 if rng.random() < 0.5 else -1.0
            sweep = turn * float(rng.uniform(math.radians(30.0), math.radians(270.0)))
            cx = x - turn * r * math.sin(heading)        # the centre on the turning side
            cy = y + turn * r * math.cos(heading)
            a0 = math.atan2(y - cy, x - cx)
            pts += _arc_points(cx, cy, r, a0, sweep, tolerance)
            x, y = pts[-1]
            heading += sweep
        contours.append(pts)
    for _ in range(int(rng.integers(2, 6))):             # holes
        r = float(rng.uniform(0.5, 5.0))
        cx, cy = base + np.array([rng.uniform(0.0, 200.0), rng.uniform(-60.0, -20.0)])
        contours.append([(cx + r, cy), *_arc_points(cx, cy, r, 0.0, 2.0 * math.pi,
                                                     tolerance)])
    for pts in nearest_first(contours, (float(base[0]), float(base[1]))):
        w.contour(pts)
    params = {"contours": len(contours), "tolerance_mm": round(tolerance, 4),
              "feed_mm_per_min": feed}
    return w.text((float(base[0]) - 20.0, float(base[1]) - 80.0)), params


def flattened_3d(rng: np.random.Generator) -> Generated:
    """A raster finishing pass over a random smooth surface, projected on XY (module doc)."""
    width, depth = float(rng.uniform(30.0, 120.0)), float(rng.uniform(10.0, 40.0))
    stepover = float(rng.uniform(0.5, 2.0))
    tolerance = float(rng.uniform(0.002, 0.01))          # the CAM's 3-D chordal tolerance
    noise = float(rng.uniform(0.5e-3, 3e-3))              # mm: the wobble of the XY path
    angle = float(rng.uniform(0.0, math.pi))             # raster direction
    feed = _feed(rng)
    waves = [(float(rng.uniform(0.5, 4.0)), float(rng.uniform(0.02, 0.2)),
              float(rng.uniform(0.0, 2.0 * math.pi))) for _ in range(3)]

    def curvature_radius(u: float) -> float:
        """Radius of curvature (mm) of the surface's section along the pass at u (mm)."""
        zpp = sum(a * k * k * math.sin(k * u + p) for a, k, p in waves)
        zp = sum(a * k * math.cos(k * u + p) for a, k, p in waves)
        return (1.0 + zp * zp) ** 1.5 / max(abs(zpp), 1e-9)

    origin = np.array([rng.uniform(100.0, 400.0), rng.uniform(100.0, 300.0)])
    along = np.array([math.cos(angle), math.sin(angle)])
    across = np.array([-along[1], along[0]])
    w = Writer(feed, 3, f"xy-twin 3-axis raster flattened, tolerance {tolerance:.4f} mm")
    pts: list[tuple[float, float]] = []
    passes = max(2, int(depth / stepover))
    for k in range(passes):
        us = [0.0]
        while us[-1] < width:                            # chords within the 3-D tolerance
            us.append(min(width, us[-1] + min(2.0, chord_length(curvature_radius(us[-1]),
                                                                tolerance))))
        us_arr = np.array(us) if k % 2 == 0 else width - np.array(us)
        wobble = rng.normal(0.0, noise, size=len(us_arr))
        for u, e in zip(us_arr, wobble, strict=True):
            p = origin + u * along + (k * stepover + e) * across
            pts.append((float(p[0]), float(p[1])))
    w.contour(pts)
    params = {"width_mm": round(width, 2), "passes": passes, "stepover_mm": round(stepover, 3),
              "tolerance_mm": round(tolerance, 4), "noise_mm": round(noise, 5),
              "feed_mm_per_min": feed}
    return w.text((float(origin[0]) - 20.0, float(origin[1]) - 20.0)), params


CLASSES: dict[str, Callable[[np.random.Generator], Generated]] = {
    "small_text": small_text, "small_radii": small_radii, "flattened_3d": flattened_3d}
"""The random classes by name."""
