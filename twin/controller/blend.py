"""Corner blending: round the kinks of a path with tangent arcs inside a tolerance.

A controller that passes a kink between two lines at speed ``v`` asks the axes for a
velocity step ``v·|t̂_out − t̂_in|`` in one period: at a 90° corner, or at every node of a
curve that CAM sent as short chords, that step is far above what the axes can follow, and
the look-ahead can only slow down. Rounding each kink with a circular arc tangent to both
lines (LinuxCNC's G64 P blending, `tp.c`) makes the path tangent-continuous: the speed
through the corner is then the arc's, capped by its centripetal acceleration like any G2/G3
arc, and a circle sent as chords runs at the speed of the same circle sent as an arc,
whatever the chord length.

Geometry of one blend, deflection θ (the angle between the incoming and the outgoing
direction, 0 = straight on) at vertex V:

* the arc of radius R touches both lines at distance ``ℓ = R·tan(θ/2)`` from V, and passes
  ``R·(1/cos(θ/2) − 1)`` from V: that is the deviation from the programmed corner, kept
  within the blend tolerance δ_b, i.e. ``R ≤ δ_b·cos(θ/2) / (1 − cos(θ/2))``;
* a blend may use at most half of each line it touches (``ℓ ≤ L/2`` of the line as
  programmed), so the two blends of one line never overlap; on a chorded curve the blends
  meet at the chords' midpoints and the rounded path is a chain of arcs of radius
  ``r·cos(θ/2)`` (r the radius the chords approximate) — within the chords' own sagitta of
  the curve they came from.

What is not blended, and stays a kink for the planner's node rule: nodes next to a rapid,
a dwell, an event (a tool switching) or the program end (exact stops); nodes where an arc
or spline meets anything (CAM arcs meet their lines tangentially; a kink there is passed
at the node limit); a deflection below ``MIN_ANGLE`` (straight on: nothing to round) or a
blend whose radius would fall below ``MIN_RADIUS`` (a reversal).

Chorded curves are faired first (`twin.controller.fair`, ``fairing``): CAM's rounding of
the vertices to the post's digits tilts short chords, and the deflections and the blends'
radii would scatter with it (a curvature step at every chord). Each vertex of a chorded
curve moves onto the circle fitted through its neighbours, by at most a tenth of the
tolerance, and the blend at a moved vertex takes the moves of it and its neighbours off its
tolerance: the rounded path stays within the tolerance of the programmed polygon.

The contour tolerance is shared: the geometric rounding takes ``share`` of it (default one
half) and the rest is left to the servo, whose dynamic error on the rounded path the
acceleration limits bound (issue 12).

A program's own path control changes the tolerance from its block on (``PathControl``):
G61 and G61.1 round nothing, ``G64 P p`` rounds within p, G64 (or ``G64 P0``) goes back to
the machine's share of the contour tolerance.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from typing import Any, NamedTuple

import numba
import numpy as np

from twin.controller.fair import FairedLines, fair
from twin.controller.gcode.items import PathControl
from twin.controller.geometry import Arc, Line, arc_span, hypot
from twin.errors import ConfigError

__all__ = ["MIN_ANGLE", "MIN_RADIUS", "BlendedBlock", "Blender", "blend_radius"]

MIN_ANGLE = 1e-7
"""Deflections below this (rad) are straight on: a step of ``v·1e-7`` is nothing."""
MIN_RADIUS = 1e-7
"""A blend tighter than this (m) is not made: the node stays a kink (an exact stop)."""
_SNAP = 1e-9
"""What is left of a line between its two blends below this (m) is nothing."""
_ARC_TOL = 4.0 * _SNAP
"""How far a blend's end may lie off its circle (m): rounding only."""
_new = tuple.__new__
"""``_new(BlendedBlock, (segment, feed, line, blend))``: the tuple without the Python-level
``__new__`` of a NamedTuple (two per blended line)."""


@numba.njit(cache=True)
def blend_radius(angle: float, room: float, tolerance: float) -> float:
    """Radius of the blend at a kink of deflection ``angle`` (rad, 0 < angle < π) (m).

    The largest radius whose arc stays within ``tolerance`` (m) of the vertex and touches
    the lines no farther than ``room`` (m) from it.
    """
    half = 0.5 * angle
    tan_half = math.tan(half)
    # R·(1/cos − 1) ≤ δ, written without the cancellation of 1 − cos for small angles
    sin_q = math.sin(0.5 * half)
    r_tol = tolerance * math.cos(half) / (2.0 * sin_q * sin_q)
    return min(r_tol, room / tan_half)


class BlendedBlock(NamedTuple):
    """A motion block of the planner's stream, before and after blending.

    Attributes
    ----------
    segment : Segment
        The line as trimmed by its blends, or the blend arc, or an untouched segment.
    feed : float or None
        Feed (m/s); a blend takes the lower feed of its two lines.
    line : int
        Source line: the programmed block's, and for a blend the outgoing block's.
    blend : bool
        True for an arc the blender inserted.
    """

    segment: Any
    feed: float | None
    line: int
    blend: bool = False


class Blender:
    """Round the line-to-line kinks of a stream of motion blocks (see the module doc).

    Parameters
    ----------
    tolerance : float
        Largest deviation of a blend from its vertex, δ_b (m), > 0.
    fairing : bool
        Fair the vertices of chorded curves first (`twin.controller.fair`); the blends
        then keep within δ_b of the programmed polygon, the vertices' moves included.

    Use ``blend(blocks)`` on an iterable of ``BlendedBlock``s (or ``(segment, feed, line)``
    tuples) and barriers: anything that is not a tuple (a dwell, an event, the program end)
    flushes the pending line unblended and passes through in order.

    The contiguous feed lines come from `twin.controller.fair` in batches (faired, or as
    programmed without ``fairing``), and each batch's corners are computed at once,
    compiled (``_corners``); a line outside a batch (in G61) is never blended.
    """

    def __init__(self, tolerance: float, *, fairing: bool = True):
        if not (math.isfinite(tolerance) and tolerance > 0.0):
            raise ConfigError("tolerance", f"must be finite and > 0 (m), got {tolerance!r}")
        self.default = self.tolerance = float(tolerance)
        self.fairing = fairing
        self.blends = 0
        """Number of arcs inserted so far."""

    def blend(self, blocks: Iterable[Any]) -> Iterator[Any]:
        """Yield ``BlendedBlock``s (and the barriers) of ``blocks`` in order.

        An exception of the source (a G-code error further on, a move outside the work zone)
        comes after the pending line, flushed unblended: what was read before it still runs.
        """
        pend: list | None = None            # the last line of the last batch (`_batch`)
        source = iter(fair(blocks, self.tolerance, self._path_tolerance, self.fairing))
        out: list[BlendedBlock] = []
        while True:
            try:
                item = next(source)
            except StopIteration:
                break
            except Exception:
                if pend is not None:
                    yield _flush(pend)
                raise
            if type(item) is FairedLines:
                try:
                    pend = self._batch(pend, item, out)
                finally:                    # a fault at a corner: what came before runs
                    yield from out
                    out.clear()
                continue
            if pend is not None:
                yield _flush(pend)
                pend = None
            if not isinstance(item, tuple):
                if type(item) is PathControl:
                    self.tolerance = self._path_tolerance(item)
                yield item
                continue
            # not a batch's line (an arc, a rapid, a line in G61): nothing to blend
            seg, feed = item[0], item[1]
            if type(seg) is Line and feed is not None:
                yield _new(BlendedBlock, (seg, feed, item[2], False))
            else:
                yield item if type(item) is BlendedBlock else _new(BlendedBlock,
                                                                   (seg, feed, item[2], False))
        if pend is not None:
            yield _flush(pend)

    # ------------------------------------------------------------------ internals
    def _path_tolerance(self, control: PathControl) -> float:
        """The blend tolerance a G61/G61.1/G64 sets: none in G61 and G61.1; in G64 its P
        when it has one > 0, else the machine's own (LinuxCNC: G64 P0 is G64)."""
        if control.mode != "blend":
            return 0.0
        return control.tolerance if control.tolerance else self.default

    def _batch(self, pend: list | None, batch: FairedLines, out: list) -> list:
        """Blend the kinks from the pending line through a batch of lines (``out`` gets the
        blocks that are done); the new pending line: [segment, origin, end, start, start's
        move, end's move, feed, line, trimmed] (its start trimmed by the blend before it
        when ``trimmed``)."""
        points, moved, lines = batch
        k = 0
        if pend is None:
            seg, feed, line = lines[0]
            if points[0] == points[1]:      # a line of zero length: its error
                Line.between(points[0], points[1])
            pend = [seg, points[0], points[1], points[0], moved[0], moved[1], feed, line,
                    False]
            k = 1
        a_seg, (ox, oy), a_end, a_start, a_m0, a_m1, a_feed, a_line, a_trim = pend
        corners = _corners(np.array(points[k:], dtype=float),
                           np.array(moved[k:], dtype=float),
                           (ox, oy, a_end[0], a_end[1], a_start[0], a_start[1], a_m0, a_m1),
                           self.tolerance)
        between, made, append, blends = Line.between, Arc.made, out.append, 0
        a_origin = pend[1]
        for c, (seg, feed, line), p0, p1, m0, m1 in zip(corners.tolist(), lines[k:],
                                                        points[k:], points[k + 1:], moved[k:],
                                                        moved[k + 1:], strict=False):
            kind = c[0]
            if kind == 0.0:                 # no blend: the line before to its end
                append(_new(BlendedBlock, (between(a_start, a_end) if a_trim or a_m0 or a_m1
                                           else a_seg, a_feed, a_line, False)))
                start, trim = p0, False
            elif kind < 0.0:                # a line of zero length: its error
                between(p0, p1)
            else:
                p_in, start, center = (c[2], c[3]), (c[4], c[5]), (c[6], c[7])
                ccw = c[11] > 0.0
                if kind == 2.0:             # off its circle: Arc's error
                    Arc.between(p_in, start, center, ccw=ccw, tol=_ARC_TOL)
                if c[1]:                    # what is left of the line before
                    append(_new(BlendedBlock, (between(a_start, p_in), a_feed, a_line, False)))
                append(_new(BlendedBlock, (made(p_in, start, center, ccw, c[8], c[9], c[10],
                                                (c[12], c[13], c[14], c[15])),
                                           a_feed if a_feed < feed else feed, line, True)))
                blends += 1
                trim = True
            a_seg, a_origin, a_end, a_start, a_m0, a_m1, a_feed, a_line, a_trim = \
                seg, p0, p1, start, m0, m1, feed, line, trim
        self.blends += blends
        return [a_seg, a_origin, a_end, a_start, a_m0, a_m1, a_feed, a_line, a_trim]


def _flush(p: list) -> BlendedBlock:
    """The pending line from its (trimmed) start to its end; untrimmed and not moved by the
    fairing, the segment as programmed."""
    seg, _, end, start, m0, m1, feed, line, trimmed = p
    if trimmed or m0 or m1:
        seg = Line.between(start, end)
    return _new(BlendedBlock, (seg, feed, line, False))


@numba.njit(cache=True)
def _corners(points, moved, pend, tolerance):  # pragma: no cover - compiled
    """The blends from a pending line through lines ``points[k] → points[k + 1]`` (m) in
    turn: per line, [kind (0 none, 1 a blend before it, 2 a blend off its circle, −1 the line
    has no length), whether the line before is left before the blend, the blend's start,
    end and centre (x, y), its radius, start angle and |sweep|, its sense (±1), its end
    tangents (`arc_span`)].

    ``pend``: the pending line's origin, end and (trimmed) start, and its vertices' moves;
    ``moved``: the points' moves (fairing). The arithmetic is the planner's `Line`
    (CPython's `hypot`) and `Arc` (`arc_span`) own."""
    ox, oy, ex, ey, sx, sy, m0, m1 = pend
    length = hypot(ex - ox, ey - oy)
    aux, auy, ahalf = (ex - ox) / length, (ey - oy) / length, 0.5 * length
    n = len(points) - 1
    out = np.zeros((n, 16))
    for k in range(n):
        bx0, by0 = points[k, 0], points[k, 1]
        bx1, by1 = points[k + 1, 0], points[k + 1, 1]
        dx, dy = bx1 - bx0, by1 - by0
        length = hypot(dx, dy)
        if length == 0.0:
            out[k, 0] = -1.0
            return out[:k + 1]
        bux, buy, bhalf = dx / length, dy / length, 0.5 * length
        bsx, bsy = bx0, by0
        cross = aux * buy - auy * bux
        dot = aux * bux + auy * buy
        angle = math.atan2(abs(cross), dot)
        if not (angle < MIN_ANGLE or tolerance == 0.0):
            room = min(ahalf, bhalf)
            # the vertices' own moves (fairing) come off the tolerance: within δ_b in all
            radius = blend_radius(angle, room, tolerance - max(m0, m1, moved[k + 1]))
            if radius >= MIN_RADIUS:
                reach = radius * math.tan(0.5 * angle)
                # the tangent points; half a line exactly is its midpoint, computed once for
                # both blends of that line so that they meet without a gap
                if reach >= ahalf:
                    px, py = 0.5 * (ox + ex), 0.5 * (oy + ey)
                else:
                    px, py = ex - reach * aux, ey - reach * auy
                if reach >= bhalf:
                    qx, qy = 0.5 * (bx0 + bx1), 0.5 * (by0 + by1)
                else:
                    qx, qy = ex + reach * bux, ey + reach * buy
                left = hypot(sx - px, sy - py) > _SNAP
                if not left:                # the blends of this line meet
                    px, py = sx, sy
                ccw = cross > 0.0
                nx, ny = (-auy, aux) if ccw else (auy, -aux)
                cx, cy = px + radius * nx, py + radius * ny
                sign = 1.0 if ccw else -1.0
                r, r_end, theta0, span, tangents = arc_span(px, py, qx, qy, cx, cy, sign, 0,
                                                            _ARC_TOL)
                out[k, 0] = 1.0 if r != 0.0 and abs(r_end - r) <= _ARC_TOL else 2.0
                out[k, 1] = 1.0 if left else 0.0
                out[k, 2], out[k, 3], out[k, 4], out[k, 5] = px, py, qx, qy
                out[k, 6], out[k, 7], out[k, 8], out[k, 9] = cx, cy, r, theta0
                out[k, 10], out[k, 11] = span, sign
                out[k, 12], out[k, 13], out[k, 14], out[k, 15] = tangents
                bsx, bsy = qx, qy
        ox, oy, ex, ey, sx, sy = bx0, by0, bx1, by1, bsx, bsy
        m0, m1 = moved[k], moved[k + 1]
        aux, auy, ahalf = bux, buy, bhalf
    return out
