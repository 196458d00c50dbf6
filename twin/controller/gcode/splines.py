"""G5 and G5.1 splines as feed lines: a cubic Bézier cut into chords within a tolerance.

The chords come from de Casteljau halving until a piece is flat: the distance of its two
inner control points from its chord bounds the curve's distance from that chord (a Bézier
lies in the convex hull of its control points), so every chord stays within ``tolerance``
of the curve. The planner then joins the chords as the curve they follow (its look-ahead
plans chains of short blocks by their curvature).
"""

from __future__ import annotations

import math

from twin.units import MM

__all__ = ["SPLINE_TOLERANCE", "bezier_chords"]

SPLINE_TOLERANCE = 0.001 * MM
"""Largest distance of a spline's chords from the curve (m)."""

_DEPTH = 24
"""Deepest halving (2^24 chords at most: far below any tolerance that makes sense)."""

Point = tuple[float, float]


def _flatness(p0: Point, p1: Point, p2: Point, p3: Point) -> float:
    """An upper bound of the distance of the Bézier p0..p3 from the segment p0-p3 (m): the
    curve lies in the hull of its control points, and the distance from a segment is convex,
    so the farther inner control point bounds it."""
    return max(_to_segment(p1, p0, p3), _to_segment(p2, p0, p3))


def _to_segment(p: Point, a: Point, b: Point) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    norm = dx * dx + dy * dy
    t = 0.0 if norm == 0.0 else min(max(((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / norm,
                                        0.0), 1.0)
    return math.hypot(p[0] - a[0] - t * dx, p[1] - a[1] - t * dy)


def bezier_chords(points: tuple[Point, Point, Point, Point], tolerance: float) -> list[Point]:
    """The chord end points of the cubic Bézier ``points`` (start excluded, end included, in
    order), each chord within ``tolerance`` of the curve (m)."""
    out: list[Point] = []
    stack = [(points, 0)]
    while stack:
        (p0, p1, p2, p3), depth = stack.pop()
        if depth >= _DEPTH or _flatness(p0, p1, p2, p3) <= tolerance:
            out.append(p3)
            continue
        m01 = ((p0[0] + p1[0]) / 2, (p0[1] + p1[1]) / 2)
        m12 = ((p1[0] + p2[0]) / 2, (p1[1] + p2[1]) / 2)
        m23 = ((p2[0] + p3[0]) / 2, (p2[1] + p3[1]) / 2)
        a = ((m01[0] + m12[0]) / 2, (m01[1] + m12[1]) / 2)
        b = ((m12[0] + m23[0]) / 2, (m12[1] + m23[1]) / 2)
        mid = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
        stack.append(((mid, b, m23, p3), depth + 1))     # the second half, done after
        stack.append(((p0, m01, a, mid), depth + 1))
    out[-1] = points[3]
    return out
