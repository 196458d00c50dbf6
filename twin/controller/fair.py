"""Fairing of chorded curves before blending: the chords' vertices put back on the curve.

CAM writes a curve as chords whose vertices lie on it, rounded to the digits of the post
(3 decimals of a millimetre: up to 0.7 µm off). On short chords that rounding tilts every
chord a little, so the deflections scatter (±13 % at a 0.063 mm chord of a 0.5 mm circle),
and with them the radii of the blends that round the kinks (`twin.controller.blend`): the
curvature then steps from blend to blend, and a law that limits jerk must pass each step at
``v²·|Δκ| ≤ J·T`` (`twin.controller.block_rules`), which confines its speed changes to a
few chords (issue 30: such a circle took 25 % longer than the same circle as a G3 arc).

Fairing moves each vertex of a chorded curve onto the circle (or line) fitted by least
squares through it and its ``REACH`` neighbours on each side — the curve the chords came
from, as far as they tell it —, and along it to smooth the chords' lengths, before the
kinks are blended:

* only vertices of a chorded curve are moved: a deflection of at most ``MAX_TURN`` whose
  blend would reach the middle of a chord (the chords are short for the tolerance:
  ``room/tan(θ/2)`` at most the tolerance's radius). A real corner, a long line, a chain's
  ends (a rapid, a dwell, an arc, the program's end next to them) stay where they are, and
  a fit does not reach across them;
* a vertex moves at most ``SHARE`` of the blend tolerance and a quarter of its shorter
  chord; a fit that would move it further is no fit of a smooth curve there, and it stays;
* the blend at a vertex then takes the tolerance less the largest move of the vertex and
  its two neighbours (``FairedLine.moved``), so the rounded path stays within the blend
  tolerance of the programmed polygon (a point of a faired chord is within the larger move
  of its ends of the programmed chord);
* a circle fitted through points of a circle is that circle: an exactly chorded circle is
  not changed (moves below ``MIN_MOVE`` are not made).

The fit is algebraic, ``A·|p|² + D·x + E·y + F = 0`` with ``|(A, D, E, F)| = 1`` (the
smallest singular vector of the rows, in coordinates local to the vertex and scaled by its
chords), so a straight run (A = 0) is a line like any other; the vertex moves along the circle's
radius, ``A·t² + g·t + F = 0`` with ``g = |(D, E)|`` solved for its root nearer zero, and
then along the circle to where a quadratic in the vertex number, fitted by least squares
to the window's places along the circle, puts it: the chords' lengths may vary smoothly
along the curve (CAM's chords follow the curvature), but not from chord to chord, where
they would leave a piece of line with a full curvature step between two blends.
The fits of many vertices are made at once (numpy), ``CHUNK`` at a time, on the programmed
points (not on points already moved), so the stream is faired in constant memory.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any, NamedTuple

import numpy as np

from twin.controller.gcode.items import PathControl
from twin.controller.geometry import Line

__all__ = ["CHUNK", "MAX_TURN", "MIN_MOVE", "REACH", "SHARE", "FairedLine", "fair",
           "fair_points"]

REACH = 4
"""Vertices on each side of a vertex that its fit takes (9 points in all)."""
SHARE = 0.1
"""Largest move of a vertex as a share of the blend tolerance (2.5 µm on laser_belt)."""
MAX_TURN = 0.5
"""Largest deflection of a chorded curve's vertex (rad, 29°): above it a corner."""
MIN_MOVE = 1e-9
"""Moves below this (m) are not made: an exactly chorded curve stays bit for bit."""
CHUNK = 256
"""Vertices fitted at once (numpy), and the memory of the stream in vertices."""
_ROOM_SHARE = 0.25
"""Largest move of a vertex as a share of its shorter chord."""


class FairedLine(NamedTuple):
    """A feed line of a chorded curve after fairing (a tuple item of the blender's stream).

    Attributes
    ----------
    segment : Line
        The line between the faired vertices.
    feed : float
        Feed (m/s).
    line : int
        Source line.
    moved : (float, float)
        How far its start and its end vertex moved (m).
    """

    segment: Any
    feed: float
    line: int
    moved: tuple[float, float]


def _curve_nodes(pts: np.ndarray, tolerance: float) -> np.ndarray:
    """Per vertex, whether it is a chorded curve's (module doc); the ends are not."""
    d = np.diff(pts, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    flags = np.zeros(len(pts), dtype=bool)
    if len(pts) < 3:
        return flags
    u = d / length[:, None]
    cross = u[:-1, 0] * u[1:, 1] - u[:-1, 1] * u[1:, 0]
    dot = u[:-1, 0] * u[1:, 0] + u[:-1, 1] * u[1:, 1]
    turn = np.arctan2(np.abs(cross), dot)
    room = 0.5 * np.minimum(length[:-1], length[1:])
    half = 0.5 * turn
    # the blend reaches the middle of a chord: room/tan(θ/2) ≤ δ·cos(θ/2)/(2·sin²(θ/4)),
    # written without dividing by the deflection (straight on is a curve node)
    s4 = np.sin(0.5 * half)
    short = room * 2.0 * s4 * s4 <= tolerance * np.cos(half) * np.tan(half)
    flags[1:-1] = (turn <= MAX_TURN) & short
    return flags


def fair_points(pts: np.ndarray, tolerance: float, first: int = 1,
                last: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The faired positions of the vertices ``first … last − 1`` of a chain (m) and how far
    each moved (m).

    Parameters
    ----------
    pts : ndarray (n, 2)
        The chain's programmed vertices (m); ``pts[0]`` and ``pts[-1]`` are its ends (or
        the ends of the part in hand: a vertex within ``REACH + 1`` of them is only right if
        they are the chain's).
    tolerance : float
        The blend tolerance (m).
    first, last : int
        The vertices wanted (default every one but the ends).
    """
    n = len(pts)
    last = n - 1 if last is None else last
    out = pts[first:last].copy()
    moved = np.zeros(len(out))
    if last <= first or n < 3:
        return out, moved
    flags = _curve_nodes(pts, tolerance)
    idx = np.arange(n)
    # the nearest vertex on each side that is no curve node: a fit does not reach past it
    stop = np.where(flags, -1, idx)
    prev_stop = np.maximum.accumulate(stop)
    stop = np.where(flags, n, idx)
    next_stop = np.minimum.accumulate(stop[::-1])[::-1]
    which = np.arange(first, last)
    which = which[flags[which]]
    if not len(which):
        return out, moved
    left = np.minimum(REACH, which - prev_stop[which])
    right = np.minimum(REACH, next_stop[which] - which)
    offsets = np.arange(-REACH, REACH + 1)
    cols = which[:, None] + offsets[None, :]
    use = (offsets[None, :] >= -left[:, None]) & (offsets[None, :] <= right[:, None])
    cols = np.clip(cols, 0, n - 1)
    d = np.diff(pts, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    scale = 0.5 * (length[which - 1] + length[which])
    local = (pts[cols] - pts[which][:, None, :]) / scale[:, None, None]
    step = _fit(local, use, offsets)
    step *= scale[:, None]
    dist = np.hypot(step[:, 0], step[:, 1])
    limit = np.minimum(SHARE * tolerance,
                       _ROOM_SHARE * np.minimum(length[which - 1], length[which]))
    move = (dist <= limit) & (dist >= MIN_MOVE)
    k = which - first
    out[k[move]] += step[move]
    moved[k[move]] = dist[move]
    return out, moved


def _fit(local: np.ndarray, use: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Where each vertex goes (local, scaled coordinates: the vertex at the origin): onto
    its fitted circle along the radius, and along the circle to where a quadratic in the
    vertex number puts it through its neighbours' places (the chords' lengths vary
    smoothly along the curve). NaN where no fit is made."""
    x, y = local[..., 0], local[..., 1]
    rows = np.stack([x * x + y * y, x, y, np.ones_like(x)], axis=-1) * use[..., None]
    # the smallest singular vector: the normal matrix's eigenvector of the least eigenvalue
    # (eigh of 4 × 4 is 3x faster than an SVD of the rows; in the chords' scale its
    # accuracy is far below MIN_MOVE)
    vec = np.linalg.eigh(np.einsum("nki,nkj->nij", rows, rows))[1]
    a, d, e, f = (vec[:, k, 0] for k in range(4))
    g = np.hypot(d, e)
    disc = g * g - 4.0 * a * f
    ok = (g > 0.0) & (disc >= 0.0) & (use.sum(axis=1) >= 4)
    g = np.where(ok, g, 1.0)
    t = np.where(ok, -2.0 * f / (g + np.sqrt(np.maximum(disc, 0.0))), 0.0)
    ux, uy = d / g, e / g                      # the radial direction (either sense)
    fx, fy = t * ux, t * uy                    # the foot on the circle
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = np.where(np.abs(a) > 1e-12 * g, np.hypot(fx + 0.5 * d / a,
                                                          fy + 0.5 * e / a), np.inf)
    wide = radius > 1e6                        # straight, in the chords' scale
    rx, ry = x - fx[:, None], y - fy[:, None]
    cross = ux[:, None] * ry - uy[:, None] * rx
    dot = ux[:, None] * rx + uy[:, None] * ry
    sign = np.where(a >= 0.0, 1.0, -1.0)[:, None]     # the centre lies at −sign·u
    radius = np.where(wide, 1.0, radius)          # unused where wide
    rr = radius[:, None]
    # arc length along the circle from the foot (centre on the −sign·u side)
    arc = np.where(wide[:, None], cross, rr * np.arctan2(sign * cross, rr + sign * dot) * sign)
    j = np.broadcast_to(offsets.astype(float), arc.shape)
    basis = np.stack([np.ones_like(arc), j, j * j], axis=-1) * use[..., None]
    normal = np.einsum("nki,nkj->nij", basis, basis)
    rhs = np.einsum("nki,nk->ni", basis, arc)
    solvable = ok & (np.abs(np.linalg.det(normal)) > 1e-12)
    normal[~solvable] = np.eye(3)
    s = np.where(solvable, np.linalg.solve(normal, rhs[..., None])[..., 0, 0], 0.0)
    phi = s / radius
    along = np.where(wide, s, radius * np.sin(phi))
    across = np.where(wide, 0.0, -2.0 * radius * np.sin(0.5 * phi) ** 2) * sign[:, 0]
    # the tangent w = (−u_y, u_x) is the direction in which `cross` counts
    sx = fx + across * ux - along * uy
    sy = fy + across * uy + along * ux
    return np.where(ok[:, None], np.stack([sx, sy], axis=1), np.nan)


def fair(items: Iterable[Any], tolerance: float,
         path_tolerance: Callable[[Any], float]) -> Iterator[Any]:
    """The stream with the vertices of its chorded curves faired (module doc).

    Feed lines come out as ``FairedLine``s; everything else passes through in order, and
    anything that is not a contiguous feed line ends a chain, and so does an exception of
    the source (after the lines read before it). ``path_tolerance`` maps a
    ``PathControl`` to the blend tolerance it sets (`Blender._path_tolerance`);
    ``tolerance`` is the one in force at the start. A tolerance of 0 (G61) fairs nothing.
    """
    chain = _Chain()
    source = iter(items)
    while True:
        try:
            item = next(source)
        except StopIteration:
            break
        except Exception:               # what was read before the fault still runs
            if chain.lines:
                yield from chain.flush(tolerance, True)
            raise
        if isinstance(item, tuple):
            seg, feed = item[0], item[1]
            if type(seg) is Line and feed is not None and tolerance > 0.0:
                start, end = seg._ends
                if chain.lines and start != chain.pts[-1]:
                    yield from chain.flush(tolerance, True)
                if not chain.lines:
                    chain.open(start)
                chain.pts.append(end)
                chain.lines.append((seg, feed, item[2]))
                if len(chain.lines) >= CHUNK + 2 * REACH + 4:
                    yield from chain.flush(tolerance, False)
                continue
        if chain.lines:
            yield from chain.flush(tolerance, True)
        if type(item) is PathControl:
            tolerance = path_tolerance(item)
        yield item
    if chain.lines:
        yield from chain.flush(tolerance, True)


class _Chain:
    """The contiguous feed lines in hand: their programmed vertices ``pts`` (a few before
    the lines as the fits' context), the final vertices ``fin`` (position, move) of the
    first of them, and the lines not yet out, the first starting at vertex ``emit``."""

    __slots__ = ("emit", "fin", "lines", "pts")

    def __init__(self):
        self.pts: list[tuple[float, float]] = []
        self.fin: list[tuple[tuple[float, float], float]] = []
        self.lines: list[tuple[Any, float, int]] = []
        self.emit = 0

    def open(self, start: tuple[float, float]) -> None:
        self.pts[:] = [start]
        self.fin[:] = [(start, 0.0)]
        self.emit = 0

    def flush(self, tolerance: float, final: bool) -> Iterator[FairedLine]:
        """Fair the vertices that can be (all when ``final``, else those whose fits read
        only vertices in hand) and yield the lines whose ends are final."""
        pts, fin = self.pts, self.fin
        n = len(pts)
        first = len(fin)
        last = n - 1 if final else n - REACH - 2
        if last > first:
            faired, moved = fair_points(np.asarray(pts), tolerance, first, last)
            fin.extend(((p[0], p[1]), m) for p, m in zip(faired.tolist(), moved.tolist(),
                                                        strict=True))
        if final:
            fin.append((pts[-1], 0.0))
        lines = self.lines
        count = min(len(lines), len(fin) - 1 - self.emit)
        for j in range(count):
            seg, feed, line = lines[j]
            (p0, m0), (p1, m1) = fin[self.emit + j], fin[self.emit + j + 1]
            if m0 or m1:
                seg = Line.between(p0, p1)
            yield FairedLine(seg, feed, line, (m0, m1))
        del lines[:count]
        self.emit += count
        if final:
            self.lines.clear()
            return
        keep = max(0, len(fin) - REACH - 2)     # vertices dropped: the rest is context
        del pts[:keep]
        del fin[:keep]
        self.emit -= keep
