"""Path segments parameterised by arc length: straight line and circular arc here, the
cubic spline in `twin.controller.spline_path`.

Every segment maps an arc length ``s`` in ``[0, length]`` (m) to a point (m), a unit tangent
and a signed curvature (1/m, positive turning left / counter-clockwise), and answers the
exact distance from any point to itself (the contour error). Values of ``s`` outside
``[0, length]`` are clipped; ``point(0)`` and ``point(length)`` return ``start`` and ``end``
exactly, so an interpolator ends on the programmed point.

Scalar calls (a Python or NumPy float) take a path without array arithmetic, for the
controller tick; array calls are vectorised: ``s`` shape (n,) gives points shape (n, 2), and
``distance`` of points shape (n, 2) gives shape (n,).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numba
import numpy as np

from twin.errors import PlanningError

__all__ = ["Arc", "Line", "Segment", "arc_span", "frozen", "hypot"]

TAU = 2.0 * math.pi


@numba.njit(cache=True)
def arc_point(cx: float, cy: float, r: float, theta0: float, k: float, sign: float,
              s: float) -> tuple[float, float, float, float]:
    """Point and unit tangent (m, 1) at arc length ``s`` of an arc about (cx, cy) of radius
    ``r`` that starts at angle ``theta0`` with signed curvature ``k`` (``sign`` +1 CCW):
    the one evaluation of an arc, for ``Arc.frame``, the interpolator and its compiled
    kernel (``twin.controller.cyclic``)."""
    phi = theta0 + k * s
    c, sn = math.cos(phi), math.sin(phi)
    return cx + r * c, cy + r * sn, -sign * sn, sign * c


_TINY = 2.2250738585072014e-308
"""The smallest normal double."""


@numba.njit(cache=True, inline="always")
def _product(x: float, y: float) -> tuple[float, float]:
    """x·y and its rounding error, exactly (Dekker's product of Veltkamp's halves)."""
    t = x * 134217729.0
    xh = t - (t - x)
    t = y * 134217729.0
    yh = t - (t - y)
    xl, yl = x - xh, y - yh
    p = xh * yh
    q = xh * yl + xl * yh
    z = p + q
    return z, p - z + q + xl * yl


@numba.njit(cache=True)
def hypot(x: float, y: float) -> float:
    """``math.hypot(x, y)`` as CPython computes it (its ``vector_norm``: a power-of-two
    scaling, exact squares, a compensated sum and one correction of the square root), bit
    for bit, compiled: the C library's ``hypot`` (NumPy's, numba's) differs from it in the
    last bit now and then, and the planner's segments take their lengths from CPython's."""
    ax, ay = abs(x), abs(y)
    if math.isinf(ax) or math.isinf(ay):
        return math.inf
    if math.isnan(ax) or math.isnan(ay):
        return math.nan
    top = ax if ax > ay else ay
    if top == 0.0:
        return top
    e = math.frexp(top)[1]
    if e < -1023:               # subnormal: 2**-e would overflow
        return _TINY * hypot(ax / _TINY, ay / _TINY)
    scale = math.ldexp(1.0, -e)
    total, frac1, frac2 = 1.0, 0.0, 0.0
    for v in (ax * scale, ay * scale):
        hi, lo = _product(v, v)
        s = total + hi
        frac2 += (total - s) + hi
        total = s
        frac1 += lo
    h = math.sqrt(total - 1.0 + (frac1 + frac2))
    hi, lo = _product(-h, h)
    s = total + hi
    frac2 += (total - s) + hi
    total = s
    frac1 += lo
    h += (total - 1.0 + (frac1 + frac2)) / (2.0 * h)
    return h / scale


@numba.njit(cache=True)
def arc_span(x0: float, y0: float, x1: float, y1: float, cx: float, cy: float, sign: float,
             turns: int, tol: float) -> tuple[float, float, float, float, tuple[float, float,
                                                                                  float, float]]:
    """(radius, end's distance from the centre, start angle, |sweep|, end tangents) of the
    arc about (cx, cy) from (x0, y0) to (x1, y1) (m, rad), ``sign`` +1 counter-clockwise,
    with ``turns`` extra full turns; an end within ``tol`` of the start is a full circle.
    The end tangents (t0x, t0y, t1x, t1y) are those of ``arc_point`` at 0 and at the
    length (`Arc.end_tangents`). The one computation of an arc's shape: ``Arc`` and the
    blender's compiled corners."""
    sx, sy, ex, ey = x0 - cx, y0 - cy, x1 - cx, y1 - cy
    theta0 = math.atan2(sy, sx)
    if hypot(ex - sx, ey - sy) <= tol:
        span = TAU
    else:
        span = ((math.atan2(ey, ex) - theta0) * sign) % TAU
    if span == 0.0:
        span = TAU
    span += TAU * turns
    radius = hypot(sx, sy)
    # θ0 + κ·length, as Arc has them (no arc without a radius: Arc's error, not ours)
    phi = theta0 + sign / radius * (radius * span) if radius != 0.0 else theta0
    tangents = (-sign * math.sin(theta0), sign * math.cos(theta0), -sign * math.sin(phi),
                sign * math.cos(phi))
    return radius, hypot(ex, ey), theta0, span, tangents


class Segment(ABC):
    """A piece of a planar path, parameterised by arc length.

    Subclasses implement :meth:`frame` (one scalar s, floats), the vectorised hooks
    ``_points``, ``_tangents``, ``_curvatures`` and ``_closest`` (s already clipped, queries
    already shaped (n, 2)), and :meth:`bounding_box`; this class dispatches between them.

    Attributes
    ----------
    start, end : ndarray, shape (2,)
        End points (m), read-only.
    length : float
        Arc length (m), > 0.
    """

    __slots__ = ()

    start: np.ndarray
    end: np.ndarray
    length: float

    @abstractmethod
    def frame(self, s: float) -> tuple[float, float, float, float, float, float]:
        """All the interpolator needs at one scalar ``s`` (clipped), as floats, in one call.

        Returns
        -------
        x, y : float
            Point (m); ``start``/``end`` exactly at the ends.
        tx, ty : float
            Unit tangent.
        curvature : float
            Signed curvature (1/m).
        curvature_rate : float
            dκ/ds (1/m²), for the normal jerk ``v³·dκ/ds``; 0 on lines and arcs.
        """

    @abstractmethod
    def bounding_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Tight axis-aligned box ``(lower (2,), upper (2,))`` containing the segment (m)."""

    @abstractmethod
    def _points(self, s: np.ndarray) -> np.ndarray: ...

    @abstractmethod
    def _tangents(self, s: np.ndarray) -> np.ndarray: ...

    @abstractmethod
    def _curvatures(self, s: np.ndarray) -> np.ndarray: ...

    @abstractmethod
    def _closest(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def point(self, s):
        """Point at arc length ``s``.

        Parameters
        ----------
        s : float or ndarray, shape (n,)
            Arc length from ``start`` (m), clipped to ``[0, length]``.

        Returns
        -------
        ndarray, shape (2,) or (n, 2)
            Position (m).
        """
        if _is_scalar(s):
            return np.array(self.frame(s)[0:2])
        s = self._clipped(s)
        out = self._points(s)
        out[s == 0.0] = self.start
        out[s == self.length] = self.end
        return out

    def tangent(self, s):
        """Unit tangent in the direction of travel at ``s``; shape (2,) or (n, 2)."""
        if _is_scalar(s):
            return np.array(self.frame(s)[2:4])
        return self._tangents(self._clipped(s))

    def curvature(self, s):
        """Signed curvature at ``s`` (1/m), > 0 turning left; float or ndarray (n,)."""
        if _is_scalar(s):
            return self.frame(s)[4]
        return self._curvatures(self._clipped(s))

    def closest(self, p):
        """Closest point of the segment to ``p``.

        Parameters
        ----------
        p : array_like, shape (2,) or (n, 2)
            Query point(s) (m).

        Returns
        -------
        s : float or ndarray, shape (n,)
            Arc length of the closest point (m) (one of them when several tie).
        distance : float or ndarray, shape (n,)
            Euclidean distance to it (m), exact up to rounding.
        """
        if np.shape(p) == (2,):
            return self._closest_one(float(p[0]), float(p[1]))
        arr = np.asarray(p, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"points must have shape (2,) or (n, 2), got {arr.shape}")
        return self._closest(arr)

    def _closest_one(self, x: float, y: float) -> tuple[float, float]:
        s, d = self._closest(np.array([[x, y]]))
        return float(s[0]), float(d[0])

    def distance(self, p):
        """Shortest distance from ``p`` (2,) or (n, 2) to the segment (m), exact."""
        return self.closest(p)[1]

    @property
    def start_tangent(self) -> np.ndarray:
        """Unit tangent at the start, shape (2,)."""
        return self.tangent(0.0)

    @property
    def end_tangent(self) -> np.ndarray:
        """Unit tangent at the end, shape (2,)."""
        return self.tangent(self.length)

    def _clipped(self, s) -> np.ndarray:
        return np.clip(np.asarray(s, dtype=float), 0.0, self.length)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(start={self.start.tolist()}, end={self.end.tolist()}, "
                f"length={self.length:.9g})")


class Line(Segment):
    """Straight segment from ``start`` to ``end`` (m); they must differ."""

    # slots: the planner makes and reads several per programmed line
    __slots__ = ("_arrays", "_ends", "_ux", "_uy", "length")

    def __init__(self, start, end):
        # floats only: the planner builds one per block; the arrays come when asked
        self._set(_pair(start, "start"), _pair(end, "end"))

    @classmethod
    def between(cls, p0: tuple[float, float], p1: tuple[float, float]) -> Line:
        """The line between two points already given as finite floats (the planner's own:
        a trimmed line of a blend), without checking them again."""
        line = cls.__new__(cls)
        line._set(p0, p1)
        return line

    def _set(self, p0: tuple[float, float], p1: tuple[float, float]) -> None:
        dx, dy = p1[0] - p0[0], p1[1] - p0[1]
        self.length = length = math.hypot(dx, dy)
        if length == 0.0:
            raise PlanningError(f"line of zero length: start = end = {list(p0)}")
        self._ux, self._uy = dx / length, dy / length
        self._ends = (p0, p1)
        self._arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def start(self) -> np.ndarray:
        return self._array(0)

    @property
    def end(self) -> np.ndarray:
        return self._array(1)

    @property
    def _u(self) -> np.ndarray:
        return self._array(2)

    def _array(self, k: int) -> np.ndarray:
        if self._arrays is None:
            self._arrays = (frozen(self._ends[0]), frozen(self._ends[1]),
                            frozen([self._ux, self._uy]))
        return self._arrays[k]

    def frame(self, s):
        if s >= self.length:
            x, y = self._ends[1]
        else:
            s = max(s, 0.0)
            x, y = self._ends[0][0] + s * self._ux, self._ends[0][1] + s * self._uy
        return x, y, self._ux, self._uy, 0.0, 0.0

    def _points(self, s):
        return self.start + s[..., None] * self._u

    def _tangents(self, s):
        return np.broadcast_to(self._u, (*s.shape, 2)).copy()

    def _curvatures(self, s):
        return np.zeros(s.shape)

    def _closest_one(self, x, y):
        px, py = x - self._ends[0][0], y - self._ends[0][1]
        s = min(max(px * self._ux + py * self._uy, 0.0), self.length)
        return s, math.hypot(px - s * self._ux, py - s * self._uy)

    def _closest(self, pts):
        rel = pts - self.start
        s = np.clip(rel @ self._u, 0.0, self.length)
        return s, np.hypot(*(rel - s[:, None] * self._u).T)

    def bounding_box(self):
        return np.minimum(self.start, self.end), np.maximum(self.start, self.end)


class Arc(Segment):
    """Circular arc about ``center`` from ``start`` to ``end`` (m).

    Parameters
    ----------
    start, end, center : array_like, shape (2,)
        End points and centre (m). ``start == end`` (within ``tol``) means a full circle.
    ccw : bool
        Direction: counter-clockwise (G3) or clockwise (G2).
    turns : int
        Extra full turns added to the sweep (≥ 0).
    tol : float
        Largest accepted ``| |end − center| − |start − center| |`` (m). The radius is
        ``|start − center|``; ``end`` must lie on that circle within ``tol`` (the parser
        enforces its own, looser tolerance before building the arc).

    Attributes
    ----------
    center : ndarray, shape (2,)
        Centre (m).
    radius : float
        Radius (m).
    sweep : float
        Signed swept angle (rad), > 0 counter-clockwise; ``|sweep| = length/radius``.
    ccw : bool
        Direction.

    Raises
    ------
    PlanningError
        Zero radius, end off the circle, bad ``ccw``/``turns``/``tol``.
    """

    __slots__ = ("_arrays", "_ends_t", "_k", "_sign", "_theta0", "_xy", "ccw", "length",
                 "radius", "sweep", "turns")

    def __init__(self, start, end, center, *, ccw: bool, turns: int = 0, tol: float = 1e-9):
        if not isinstance(ccw, bool | np.bool_):
            raise PlanningError(f"ccw must be a bool, got {ccw!r}")
        if isinstance(turns, bool) or not isinstance(turns, int | np.integer) or turns < 0:
            raise PlanningError(f"turns must be an integer ≥ 0, got {turns!r}")
        if not (math.isfinite(tol) and tol >= 0.0):
            raise PlanningError(f"tol must be finite and ≥ 0 (m), got {tol!r}")
        self._set(_pair(start, "start"), _pair(end, "end"), _pair(center, "center"), ccw,
                  int(turns), tol)

    @classmethod
    def between(cls, p0: tuple[float, float], p1: tuple[float, float],
                c: tuple[float, float], *, ccw: bool, tol: float) -> Arc:
        """The arc of less than a turn between points already given as finite floats (the
        planner's own: a blend), without checking its arguments again; its end is still
        checked on the circle."""
        arc = cls.__new__(cls)
        arc._set(p0, p1, c, ccw, 0, tol)
        return arc

    @classmethod
    def made(cls, p0: tuple[float, float], p1: tuple[float, float], c: tuple[float, float],
             ccw: bool, radius: float, theta0: float, span: float,
             tangents: tuple[float, float, float, float]) -> Arc:
        """The arc of less than a turn between points already given as finite floats whose
        radius, start angle, |sweep| and end tangents `arc_span` has given and whose end
        the caller has checked on the circle (the blender's compiled corners)."""
        arc = cls.__new__(cls)
        arc._fill(p0, p1, c, ccw, 0, radius, theta0, span, tangents)
        return arc

    def _set(self, p0: tuple[float, float], p1: tuple[float, float], c: tuple[float, float],
             ccw: bool, turns: int, tol: float) -> None:
        radius, end_radius, theta0, span, tangents = arc_span(
            p0[0], p0[1], p1[0], p1[1], c[0], c[1], 1.0 if ccw else -1.0, turns, tol)
        if radius == 0.0:
            raise PlanningError(f"arc of zero radius: start = center = {list(p0)}")
        if abs(end_radius - radius) > tol:
            raise PlanningError(
                f"arc end point is not on the circle: |end − center| = {end_radius!r} m, "
                f"|start − center| = {radius!r} m, difference "
                f"{abs(end_radius - radius):.3g} m > tol = {tol:.3g} m")
        self._fill(p0, p1, c, ccw, turns, radius, theta0, span, tangents)

    def _fill(self, p0: tuple[float, float], p1: tuple[float, float], c: tuple[float, float],
              ccw: bool, turns: int, radius: float, theta0: float, span: float,
              tangents: tuple[float, float, float, float]) -> None:
        sign = 1.0 if ccw else -1.0
        self.radius, self.ccw, self._sign, self._theta0 = radius, bool(ccw), sign, theta0
        self.turns = int(turns)
        self.sweep = sign * span
        self.length = radius * span
        self._k = sign / radius
        self._xy = (*c, *p0, *p1)
        self._ends_t = tangents
        self._arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def start(self) -> np.ndarray:
        return self._array(0)

    @property
    def end(self) -> np.ndarray:
        return self._array(1)

    @property
    def center(self) -> np.ndarray:
        return self._array(2)

    def _array(self, k: int) -> np.ndarray:
        if self._arrays is None:
            cx, cy, x0, y0, x1, y1 = self._xy
            self._arrays = (frozen((x0, y0)), frozen((x1, y1)), frozen((cx, cy)))
        return self._arrays[k]

    def frame(self, s):
        s = min(max(s, 0.0), self.length)
        cx, cy, x0, y0, x1, y1 = self._xy
        x, y, tx, ty = arc_point(cx, cy, self.radius, self._theta0, self._k, self._sign, s)
        if s == self.length:
            x, y = x1, y1
        elif s == 0.0:
            x, y = x0, y0
        return x, y, tx, ty, self._k, 0.0

    def end_tangents(self) -> tuple[float, float, float, float]:
        """Unit tangents at the start and at the end, (t0x, t0y, t1x, t1y): those of
        ``frame(0)`` and ``frame(length)``, in the same arithmetic as ``arc_point``, for
        the planner's blocks without two compiled calls."""
        return self._ends_t                 # `arc_span` computed them with the arc

    def _points(self, s):
        phi = self._theta0 + self._k * s
        return self.center + self.radius * np.stack((np.cos(phi), np.sin(phi)), axis=-1)

    def _tangents(self, s):
        phi = self._theta0 + self._k * s
        return self._sign * np.stack((-np.sin(phi), np.cos(phi)), axis=-1)

    def _curvatures(self, s):
        return np.full(s.shape, self._k)

    def _closest_one(self, x, y):
        cx, cy, x0, y0, x1, y1 = self._xy
        rho = math.hypot(x - cx, y - cy)
        if rho == 0.0:
            return 0.0, self.radius
        offset = ((math.atan2(y - cy, x - cx) - self._theta0) * self._sign) % TAU
        if offset <= abs(self.sweep) or abs(self.sweep) >= TAU:
            return self.radius * offset, abs(rho - self.radius)
        to_start, to_end = math.hypot(x - x0, y - y0), math.hypot(x - x1, y - y1)
        return (self.length, to_end) if to_end < to_start else (0.0, to_start)

    def _closest(self, pts):
        rel = pts - self.center
        rho = np.hypot(*rel.T)
        offset = ((np.arctan2(rel[:, 1], rel[:, 0]) - self._theta0) * self._sign) % TAU
        inside = (offset <= abs(self.sweep)) | (abs(self.sweep) >= TAU)
        to_start = np.hypot(*(pts - self.start).T)
        to_end = np.hypot(*(pts - self.end).T)
        s = np.where(inside, self.radius * offset, np.where(to_end < to_start, self.length, 0.0))
        d = np.where(inside, np.abs(rho - self.radius), np.minimum(to_start, to_end))
        at_center = rho == 0.0
        s[at_center], d[at_center] = 0.0, self.radius
        return s, d

    def bounding_box(self):
        pts = [self.start, self.end]
        for k, axis_point in enumerate(((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))):
            offset = ((k * math.pi / 2 - self._theta0) * self._sign) % TAU
            if offset <= abs(self.sweep):
                pts.append(self.center + self.radius * np.array(axis_point))
        pts = np.array(pts)
        return pts.min(axis=0), pts.max(axis=0)


def _is_scalar(s) -> bool:
    return isinstance(s, float | int | np.floating | np.integer)


def frozen(values) -> np.ndarray:
    """A float array that cannot be written (a segment's points are shared, not copied)."""
    arr = np.array(values, dtype=float)
    arr.setflags(write=False)
    return arr


def _pair(value, name: str) -> tuple[float, float]:
    """A finite point as two floats (no array): what the planner's hot path builds."""
    try:
        x, y = value
        x, y = float(x), float(y)
    except (TypeError, ValueError):
        x = y = math.nan
    if not (math.isfinite(x) and math.isfinite(y)):
        raise PlanningError(f"{name} must be a finite point of shape (2,), got {value!r}")
    return x, y


def _point(value, name: str) -> np.ndarray:
    arr = frozen(value)
    if arr.shape != (2,) or not np.isfinite(arr).all():
        raise PlanningError(f"{name} must be a finite point of shape (2,), got {value!r}")
    return arr
