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
  its two neighbours (``FairedLines.moved``), so the rounded path stays within the blend
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
The fits of many vertices are made at once (compiled loops around NumPy's eigenvectors and
solves), ``CHUNK`` at a time, on the programmed points (not on points already moved), so
the stream is faired in constant memory.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from typing import Any, NamedTuple

import numba
import numpy as np

from twin.controller.gcode.items import PathControl
from twin.controller.geometry import Line

__all__ = ["CHUNK", "MAX_TURN", "MIN_MOVE", "REACH", "SHARE", "FairedLines", "fair",
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


class FairedLines(NamedTuple):
    """Consecutive feed lines of a chain after fairing (one item of the blender's stream).

    Attributes
    ----------
    points : list of (float, float)
        Their final vertices (m), one more than the lines: line k runs from ``points[k]``
        to ``points[k + 1]``.
    moved : list of float
        How far each vertex moved (m).
    lines : list of (Line, float, int)
        The lines as programmed: segment, feed (m/s), source line.
    """

    points: list[tuple[float, float]]
    moved: list[float]
    lines: list[tuple[Any, float, int]]


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
    which, x, y, weight, scale, limit = _windows(pts, flags, first, last, tolerance)
    if len(which):
        _place(_fit(x, y, weight), scale, limit, which - first, out, moved)
    return out, moved


@numba.njit(cache=True)
def _windows(pts, flags, first, last, tolerance):  # pragma: no cover - compiled
    """The curve nodes among the vertices ``first … last − 1`` and their fits' windows: the
    ``REACH`` vertices on each side, up to the nearest vertex that is no curve node (a fit
    does not reach past it: ``weight`` 0 beyond), in coordinates local to the vertex and
    scaled by its chords (``x``, ``y``: the vertex at the origin, ``scale`` the mean of its
    chords); ``limit``: the largest move of each (m)."""
    n = len(pts)
    prev_stop = np.empty(n, np.int64)
    next_stop = np.empty(n, np.int64)
    stop = -1
    for i in range(n):
        if not flags[i]:
            stop = i
        prev_stop[i] = stop
    stop = n
    for i in range(n - 1, -1, -1):
        if not flags[i]:
            stop = i
        next_stop[i] = stop
    length = np.empty(n - 1)
    for i in range(n - 1):
        length[i] = math.hypot(pts[i + 1, 0] - pts[i, 0], pts[i + 1, 1] - pts[i, 1])
    which = np.array([i for i in range(first, last) if flags[i]], dtype=np.int64)
    m, width = len(which), 2 * REACH + 1
    x, y, weight = np.empty((m, width)), np.empty((m, width)), np.empty((m, width))
    scale, limit = np.empty(m), np.empty(m)
    for q in range(m):
        i = which[q]
        left, right = min(REACH, i - prev_stop[i]), min(REACH, next_stop[i] - i)
        sc = 0.5 * (length[i - 1] + length[i])
        for o in range(-REACH, REACH + 1):
            col = min(max(i + o, 0), n - 1)
            x[q, o + REACH] = (pts[col, 0] - pts[i, 0]) / sc
            y[q, o + REACH] = (pts[col, 1] - pts[i, 1]) / sc
            weight[q, o + REACH] = 1.0 if -left <= o <= right else 0.0
        scale[q] = sc
        limit[q] = min(SHARE * tolerance, _ROOM_SHARE * min(length[i - 1], length[i]))
    return which, x, y, weight, scale, limit


@numba.njit(cache=True)
def _place(step, scale, limit, k, out, moved):  # pragma: no cover - compiled
    """Move the vertices ``k`` of ``out`` by their fits' ``step`` (scaled coordinates) where
    it is a move of at least ``MIN_MOVE`` and at most ``limit``; ``moved``: how far."""
    for q in range(len(k)):
        sx, sy = step[q, 0] * scale[q], step[q, 1] * scale[q]
        dist = math.hypot(sx, sy)
        if dist <= limit[q] and dist >= MIN_MOVE:
            out[k[q], 0] += sx
            out[k[q], 1] += sy
            moved[k[q]] = dist


def _fit(x: np.ndarray, y: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Where each vertex goes (local, scaled coordinates ``x``, ``y`` of its window, the
    vertex at the origin; ``weight`` 1 for the points its fit takes, else 0): onto its
    fitted circle along the radius, and along the circle to where a quadratic in the
    vertex number puts it through its neighbours' places (the chords' lengths vary
    smoothly along the curve). NaN where no fit is made.

    The arithmetic runs compiled (``_normal_matrices``, ``_circles``, ``_along``,
    ``_steps``), element by element in NumPy's own order of operations; the eigenvectors,
    the solves, and the arc tangent stay NumPy's (LAPACK, and NumPy's own vectorised
    ``arctan2``), so the result is NumPy's bit for bit."""
    # the smallest singular vector of the rows (|p|², x, y, 1): the normal matrix's
    # eigenvector of the least eigenvalue (eigh of 4 × 4 is 3x faster than an SVD of the
    # rows; in the chords' scale its accuracy is far below MIN_MOVE)
    vec = np.linalg.eigh(_normal_matrices(x, y, weight))[1]
    circle, num, den = _circles(np.ascontiguousarray(vec[:, :, 0]), x, y, weight)
    normal, rhs = _along(np.arctan2(num, den), num, circle, weight,
                         np.arange(-REACH, REACH + 1.0))
    ok = circle[:, 0] != 0.0
    # with ≥ 4 distinct vertex numbers the quadratic's normal matrix is regular (its
    # determinant is ≥ 4): every fit (ok) is solvable
    normal[~ok] = np.eye(3)
    s = np.linalg.solve(normal, rhs[..., None])[..., 0, 0]
    return _steps(s, circle)


@numba.njit(cache=True)
def _normal_matrices(x, y, weight):  # pragma: no cover - compiled
    """Σ_k r_k r_kᵀ of the rows r = (x² + y², x, y, 1)·w per vertex (n, 4, 4)."""
    n, m = x.shape
    out = np.empty((n, 4, 4))
    row = np.empty((m, 4))
    for q in range(n):
        for k in range(m):
            xk, yk, w = x[q, k], y[q, k], weight[q, k]
            row[k, 0] = (xk * xk + yk * yk) * w
            row[k, 1] = xk * w
            row[k, 2] = yk * w
            row[k, 3] = 1.0 * w
        _gram(row, out[q])
    return out


@numba.njit(cache=True, inline="always")
def _gram(rows, out):  # pragma: no cover - compiled
    """out = rowsᵀ·rows, summed over the rows in their order (the normal matrix)."""
    m, c = rows.shape
    for i in range(c):
        for j in range(c):
            acc = 0.0
            for k in range(m):
                acc += rows[k, i] * rows[k, j]
            out[i, j] = acc


# per vertex in ``circle``: ok (1.0 or 0.0), the foot (fx, fy), the radial direction
# (ux, uy), the radius (1.0 where wide), wide (1.0 or 0.0), the sign of A
_OK, _FX, _FY, _UX, _UY, _RADIUS, _WIDE, _SIGN = range(8)


@numba.njit(cache=True)
def _circles(vec, x, y, weight):  # pragma: no cover - compiled
    """The fitted circle of each vertex from its eigenvector (a, d, e, f) (``circle``, the
    columns above), and per point the arc tangent's arguments sign·cross, r + sign·dot (the
    point's angle along the circle from the foot)."""
    n, m = x.shape
    circle = np.empty((n, 8))
    num = np.empty((n, m))
    den = np.empty((n, m))
    for q in range(n):
        a, d, e, f = vec[q, 0], vec[q, 1], vec[q, 2], vec[q, 3]
        g = math.hypot(d, e)
        disc = g * g - 4.0 * a * f
        used = 0.0
        for k in range(m):
            used += weight[q, k]
        ok = g > 0.0 and disc >= 0.0 and used >= 4.0
        if not ok:
            g = 1.0
        t = -2.0 * f / (g + math.sqrt(max(disc, 0.0))) if ok else 0.0
        ux, uy = d / g, e / g                  # the radial direction (either sense)
        fx, fy = t * ux, t * uy                # the foot on the circle
        radius = math.inf
        if abs(a) > 1e-12 * g:
            radius = math.hypot(fx + 0.5 * d / a, fy + 0.5 * e / a)
        wide = radius > 1e6                    # straight, in the chords' scale
        sign = 1.0 if a >= 0.0 else -1.0      # the centre lies at −sign·u
        if wide:
            radius = 1.0                       # unused where wide
        circle[q, _OK] = 1.0 if ok else 0.0
        circle[q, _FX], circle[q, _FY], circle[q, _UX], circle[q, _UY] = fx, fy, ux, uy
        circle[q, _RADIUS], circle[q, _WIDE], circle[q, _SIGN] = radius, wide, sign
        for k in range(m):
            rx, ry = x[q, k] - fx, y[q, k] - fy
            cross = ux * ry - uy * rx
            dot = ux * rx + uy * ry
            # wide: the arc length is `cross` itself (kept in num, den unused)
            num[q, k] = cross if wide else sign * cross
            den[q, k] = 1.0 if wide else radius + sign * dot
    return circle, num, den


@numba.njit(cache=True)
def _along(angle, num, circle, weight, offsets):  # pragma: no cover - compiled
    """Each point's arc length along its vertex's circle from the foot, and the normal
    equations (n, 3, 3), (n, 3) of the quadratic in the vertex number through them."""
    n, m = num.shape
    normal = np.empty((n, 3, 3))
    rhs = np.empty((n, 3))
    basis = np.empty((m, 3))
    arc = np.empty(m)
    for q in range(n):
        radius, sign = circle[q, _RADIUS], circle[q, _SIGN]
        wide = circle[q, _WIDE] != 0.0
        for k in range(m):
            arc[k] = num[q, k] if wide else radius * angle[q, k] * sign
            j, w = offsets[k], weight[q, k]
            basis[k, 0] = 1.0 * w
            basis[k, 1] = j * w
            basis[k, 2] = j * j * w
        _gram(basis, normal[q])
        for i in range(3):
            acc = 0.0
            for k in range(m):
                acc += basis[k, i] * arc[k]
            rhs[q, i] = acc
    return normal, rhs


@numba.njit(cache=True)
def _steps(s, circle):  # pragma: no cover - compiled
    """The vertex's place on its circle at arc length ``s`` from the foot (n, 2); NaN
    where no fit is made."""
    n = len(s)
    out = np.empty((n, 2))
    for q in range(n):
        if circle[q, _OK] == 0.0:
            out[q, 0] = out[q, 1] = math.nan
            continue
        fx, fy, ux, uy = circle[q, _FX], circle[q, _FY], circle[q, _UX], circle[q, _UY]
        radius, sign = circle[q, _RADIUS], circle[q, _SIGN]
        if circle[q, _WIDE] != 0.0:
            along, across = s[q], 0.0 * sign
        else:
            phi = s[q] / radius
            half = math.sin(0.5 * phi)
            along = radius * math.sin(phi)
            across = -2.0 * radius * (half * half) * sign
        # the tangent w = (−u_y, u_x) is the direction in which `cross` counts
        out[q, 0] = fx + across * ux - along * uy
        out[q, 1] = fy + across * uy + along * ux
    return out


def fair(items: Iterable[Any], tolerance: float, path_tolerance: Callable[[Any], float],
         fit: bool = True) -> Iterator[Any]:
    """The stream with the vertices of its chorded curves faired (module doc).

    The feed lines of a chain come out as ``FairedLines``, a batch at a time (up to about
    ``CHUNK``); everything else passes through in order, and anything that is not a
    contiguous feed line ends a chain, and so does an exception of the source (after the
    lines read before it). ``path_tolerance`` maps a ``PathControl`` to the blend
    tolerance it sets (`Blender._path_tolerance`); ``tolerance`` is the one in force at
    the start. A tolerance of 0 (G61) chains and fairs nothing (the lines pass through);
    ``fit`` False chains the lines without moving a vertex.
    """
    chain = _Chain()
    pts, lines = chain.pts, chain.lines     # the chain's own lists: emptied, never replaced
    full = CHUNK + 2 * REACH + 4
    source = iter(items)
    while True:
        try:
            item = next(source)
        except StopIteration:
            break
        except Exception:               # what was read before the fault still runs
            if chain.lines:
                yield from chain.flush(tolerance, True, fit)
            raise
        if isinstance(item, tuple):
            seg, feed = item[0], item[1]
            if type(seg) is Line and feed is not None and tolerance > 0.0:
                start, end = seg._ends
                if not lines:
                    chain.open(start)
                elif start != pts[-1]:          # not contiguous: a chain of its own
                    yield from chain.flush(tolerance, True, fit)
                    chain.open(start)
                pts.append(end)
                lines.append((seg, feed, item[2]))
                if len(lines) >= full:
                    yield from chain.flush(tolerance, False, fit)
                continue
        if lines:
            yield from chain.flush(tolerance, True, fit)
        if type(item) is PathControl:
            tolerance = path_tolerance(item)
        yield item
    if chain.lines:
        yield from chain.flush(tolerance, True, fit)


class _Chain:
    """The contiguous feed lines in hand: their programmed vertices ``pts`` (a few before
    the lines as the fits' context), the final vertices ``fin`` and their moves ``moved``
    from the first of them on, and the lines not yet out, the first starting at vertex
    ``emit``."""

    __slots__ = ("emit", "fin", "lines", "moved", "pts")

    def __init__(self):
        self.pts: list[tuple[float, float]] = []
        self.fin: list[tuple[float, float]] = []
        self.moved: list[float] = []
        self.lines: list[tuple[Any, float, int]] = []
        self.emit = 0

    def open(self, start: tuple[float, float]) -> None:
        self.pts[:] = [start]
        self.fin[:] = [start]
        self.moved[:] = [0.0]
        self.emit = 0

    def flush(self, tolerance: float, final: bool, fit: bool) -> Iterator[FairedLines]:
        """Fair the vertices that can be (all when ``final``, else those whose fits read
        only vertices in hand) and yield the lines whose ends are final, as one batch."""
        pts, fin, moves = self.pts, self.fin, self.moved
        n = len(pts)
        first = len(fin)
        last = n - 1 if final else n - REACH - 2
        if last > first:
            if fit:
                faired, moved = fair_points(np.asarray(pts), tolerance, first, last)
                fin.extend(zip(faired[:, 0].tolist(), faired[:, 1].tolist(), strict=True))
                moves.extend(moved.tolist())
            else:
                fin.extend(pts[first:last])
                moves.extend([0.0] * (last - first))
        if final:
            fin.append(pts[-1])
            moves.append(0.0)
        lines, emit = self.lines, self.emit
        count = min(len(lines), len(fin) - 1 - emit)
        if count > 0:
            yield FairedLines(fin[emit:emit + count + 1], moves[emit:emit + count + 1],
                              lines[:count])
        if final:
            self.lines.clear()
            return
        del lines[:count]
        self.emit += count
        keep = max(0, len(fin) - REACH - 2)     # vertices dropped: the rest is context
        del pts[:keep]
        del fin[:keep]
        del moves[:keep]
        self.emit -= keep
