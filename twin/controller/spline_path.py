"""The cubic-spline path segment: a natural cubic spline through points, parameterised by
arc length, with the `twin.controller.geometry.Segment` interface (point, tangent,
curvature, exact distance) of the lines and arcs."""

from __future__ import annotations

import numpy as np

from twin.controller._spline_curve import SplineCurve
from twin.controller.geometry import Segment, frozen
from twin.errors import PlanningError

__all__ = ["SplinePath"]


class SplinePath(Segment):
    """Parametric natural cubic spline through points, parameterised by arc length.

    ``x(u)`` and ``y(u)`` are natural cubic splines (:mod:`twin.controller.spline`) of the
    cumulative chord length ``u``. Arc length is integrated per piece by adaptive
    Gauss–Legendre quadrature (8 nodes, sub-intervals refined until 1e-13 relative);
    ``s → u`` is inverted by safeguarded Newton from a fitted initial guess; the exact
    distance minimises the squared distance per piece through the real roots of its
    derivative, a quintic. See ``twin.controller._spline_curve``.

    Parameters
    ----------
    points : array_like, shape (n, 2)
        Points to pass through (m), n ≥ 2, consecutive points distinct.
    method : {"tridiagonal", "blocks4"}
        Solver of the spline coefficients (same spline either way).

    Attributes
    ----------
    points : ndarray, shape (n, 2)
        The points (m).
    pieces : int
        Number of cubic pieces, n − 1.
    knot_s : ndarray, shape (n,)
        Arc length at each point (m).
    """

    def __init__(self, points, *, method: str = "tridiagonal"):
        pts = np.array(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
            raise PlanningError(f"points must have shape (n ≥ 2, 2), got {pts.shape}")
        bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
        if bad.size:
            raise PlanningError(f"points[{bad[0]}] is not finite: {pts[bad[0]].tolist()}")
        same = np.flatnonzero((np.diff(pts, axis=0) == 0.0).all(axis=1))
        if same.size:
            k = same[0] + 1
            raise PlanningError(f"points[{k}] repeats points[{k - 1}] = {pts[k].tolist()}: "
                                "consecutive points must differ")
        self.points = frozen(pts)
        self._curve = SplineCurve(pts, method=method)
        self.pieces = pts.shape[0] - 1
        self.knot_s = self._curve.knot_s
        self.length = float(self.knot_s[-1])
        self.start = frozen(pts[0])
        self.end = frozen(pts[-1])

    def frame(self, s):
        s = min(max(s, 0.0), self.length)
        x, y, tx, ty, k, rate = self._curve.frame_at(s)
        if s == 0.0 or s == self.length:
            x, y = (self.start if s == 0.0 else self.end).tolist()
        return x, y, tx, ty, k, rate

    def kernel_tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The curve's tables for the compiled tick (``SplineCurve.kernel_tables``)."""
        return self._curve.kernel_tables()

    def _points(self, s):
        return self._curve.points_at(s)

    def _tangents(self, s):
        return self._curve.tangents_at(s)

    def _curvatures(self, s):
        return self._curve.curvatures_at(s)

    def _closest(self, pts):
        return self._curve.closest(pts)

    def bounding_box(self):
        return self._curve.box_lower.min(axis=0), self._curve.box_upper.max(axis=0)
