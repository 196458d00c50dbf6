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

from twin.controller.fair import FairedLine, fair
from twin.controller.gcode.items import PathControl
from twin.controller.geometry import Arc, Line
from twin.errors import ConfigError

__all__ = ["MIN_ANGLE", "MIN_RADIUS", "BlendedBlock", "Blender", "blend_radius"]

MIN_ANGLE = 1e-7
"""Deflections below this (rad) are straight on: a step of ``v·1e-7`` is nothing."""
MIN_RADIUS = 1e-7
"""A blend tighter than this (m) is not made: the node stays a kink (an exact stop)."""
_SNAP = 1e-9
"""What is left of a line between its two blends below this (m) is nothing."""
_STILL = (0.0, 0.0)
"""The moves of a line's vertices that fairing did not touch."""


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


class _Pending:
    """A line waiting for its successor: as programmed (``segment``, ``origin``, ``end``),
    and its start as already trimmed by the blend before it (``start``)."""

    __slots__ = ("end", "feed", "half", "line", "moved", "origin", "segment", "start", "ux",
                 "uy")


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
        pend: _Pending | None = None
        source = iter(fair(blocks, self.tolerance, self._path_tolerance) if self.fairing
                      else blocks)
        while True:
            try:
                item = next(source)
            except StopIteration:
                break
            except Exception:
                if pend is not None:
                    yield self._flush(pend)
                raise
            if not isinstance(item, tuple):
                if pend is not None:
                    yield self._flush(pend)
                    pend = None
                if type(item) is PathControl:
                    self.tolerance = self._path_tolerance(item)
                yield item
                continue
            seg, feed, line = item[0], item[1], item[2]
            if type(seg) is not Line or feed is None:
                if pend is not None:
                    yield self._flush(pend)
                    pend = None
                yield item if type(item) is BlendedBlock else BlendedBlock(seg, feed, line)
                continue
            nxt = _Pending()
            nxt.segment = seg
            nxt.origin, nxt.end = seg._ends
            nxt.start = nxt.origin
            nxt.ux, nxt.uy = seg._ux, seg._uy
            nxt.half = 0.5 * seg.length
            nxt.feed, nxt.line = feed, line
            nxt.moved = item[3] if type(item) is FairedLine else _STILL
            if pend is None:
                pend = nxt
                continue
            arc = self._corner(pend, nxt)
            if arc is None:
                yield self._flush(pend)
            else:
                trimmed, corner = arc
                if trimmed is not None:
                    yield trimmed
                yield corner
            pend = nxt
        if pend is not None:
            yield self._flush(pend)

    # ------------------------------------------------------------------ internals
    def _path_tolerance(self, control: PathControl) -> float:
        """The blend tolerance a G61/G61.1/G64 sets: none in G61 and G61.1; in G64 its P
        when it has one > 0, else the machine's own (LinuxCNC: G64 P0 is G64)."""
        if control.mode != "blend":
            return 0.0
        return control.tolerance if control.tolerance else self.default

    @staticmethod
    def _flush(p: _Pending) -> BlendedBlock:
        """The pending line from its trimmed start to its programmed end."""
        seg = p.segment if p.start is p.origin else Line.between(p.start, p.end)
        return BlendedBlock(seg, p.feed, p.line)

    def _corner(self, a: _Pending, b: _Pending) -> tuple[BlendedBlock | None, BlendedBlock] | None:
        """Blend the kink between ``a`` (pending) and ``b`` (next): the trimmed ``a`` (None
        if nothing is left of it) and the arc; ``b.start`` is trimmed. None: no blend."""
        cross = a.ux * b.uy - a.uy * b.ux
        dot = a.ux * b.ux + a.uy * b.uy
        angle = math.atan2(abs(cross), dot)
        if angle < MIN_ANGLE or self.tolerance == 0.0:
            return None
        room = min(a.half, b.half)
        # the vertices' own moves (fairing) come off the tolerance: within δ_b in all
        tolerance = self.tolerance - max(a.moved[0], a.moved[1], b.moved[1])
        radius = blend_radius(angle, room, tolerance)
        if not radius >= MIN_RADIUS:
            return None
        reach = radius * math.tan(0.5 * angle)
        vx, vy = a.end
        # the tangent points; half a line exactly is its midpoint, computed once for both
        # blends of that line so that they meet without a gap
        p_in = _midpoint(a) if reach >= a.half else (vx - reach * a.ux, vy - reach * a.uy)
        p_out = _midpoint(b) if reach >= b.half else (vx + reach * b.ux, vy + reach * b.uy)
        trimmed = None
        if math.dist(a.start, p_in) > _SNAP:
            trimmed = BlendedBlock(Line.between(a.start, p_in), a.feed, a.line)
        else:                               # the blends of this line meet
            p_in = a.start
        ccw = cross > 0.0
        nx, ny = (-a.uy, a.ux) if ccw else (a.uy, -a.ux)
        center = (p_in[0] + radius * nx, p_in[1] + radius * ny)
        arc = Arc.between(p_in, p_out, center, ccw=ccw, tol=4.0 * _SNAP)
        self.blends += 1
        b.start = p_out
        feed = a.feed if a.feed < b.feed else b.feed
        return trimmed, BlendedBlock(arc, feed, b.line, blend=True)


def _midpoint(p: _Pending) -> tuple[float, float]:
    (x0, y0), (x1, y1) = p.origin, p.end
    return (0.5 * (x0 + x1), 0.5 * (y0 + y1))
