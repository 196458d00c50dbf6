"""The corner model of a shaped reference: the planner slows at a node for the corner the
input shapers cut as well as for the loop's own lag.

A shaper is a convex combination of the reference's past points (``twin.controller.shaping``):
at a node passed at speed V it cuts the corner by ``κ(α)·V``, linear in V, where κ depends
only on the deflection angle α and the shapers' impulses. For the path ``p(s) = s·u_in``
(s < 0), ``s·u_out`` (s ≥ 0) at unit speed, each axis' shaped reference is
``q_k(t) = Σ A_ki·p_k(t − t_ki)``; κ(α) is the largest distance of q from the two legs,
over t and over the orientation of the corner on the table (it matters only when x and y
have different shapers). ``ShapedCornerModel`` adds κ(α) to the relative error
``δ* = tolerance / V_node`` of the planner's model: the loop's error and the shaper's
are added, a bound (the loop follows the shaped, smoother corner at least as well).

Curves. A curve of radius R run at v through the shapers shrinks by ``≈ v²σ²/(2R)``
(``shaping.circle_error``; σ² the impulses' time variance): by the centripetal acceleration
times σ²/2, whatever the radius. ``curve_acceleration`` is the centripetal acceleration
that keeps this within a share of the contour tolerance (``controller.shaper.curve_share``,
default ``SHAPER_SHARE``); the planner caps the speed on arcs, blends and splines by it
(``Planner(curve_acceleration=...)``). It costs cycle time on a job of small curves: the
quick laser nest on laser_belt ran 39 % longer with EI at the default share.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from twin.controller.corner import CornerModel
from twin.controller.shaping import InputShaper

__all__ = ["SHAPER_SHARE", "ShapedCornerModel", "curve_acceleration", "shaper_corner_error"]

SHAPER_SHARE = 0.25
"""Share of the contour tolerance a shaped curve may lose to the shapers (the blends take
``corner_blend``, half by default, and the loop the rest)."""

_ANGLES = np.linspace(0.0, math.pi, 61)
_ORIENTATIONS = np.linspace(0.0, math.pi, 8, endpoint=False)


def _ray_distance(q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Distance of points q (..., 2) from the ray {s·u, s ≥ 0} (u a unit vector (..., 2))."""
    along = np.sum(q * u, axis=-1)
    perp = np.abs(q[..., 0] * u[..., 1] - q[..., 1] * u[..., 0])
    return np.where(along >= 0.0, perp, np.hypot(q[..., 0], q[..., 1]))


def shaper_corner_error(shapers: Sequence[InputShaper | None], angle, *,
                        samples: int = 801) -> np.ndarray:
    """κ(α): how far the shaped reference cuts a corner of deflection ``angle`` (rad,
    scalar or array) per unit node speed (s); see the module docstring. None in
    ``shapers``: that axis unshaped (one impulse at 0)."""
    imp = [(np.asarray(s.amplitudes), np.asarray(s.times)) if s is not None
           else (np.ones(1), np.zeros(1)) for s in shapers]
    span = max(float(t[-1]) for _, t in imp)
    if span == 0.0:
        return np.zeros_like(np.asarray(angle, dtype=float))
    alpha = np.atleast_1d(np.asarray(angle, dtype=float))
    t = np.linspace(0.0, span, samples)
    out = np.zeros(alpha.shape)
    for theta in _ORIENTATIONS:
        u_in = np.array([math.cos(theta), math.sin(theta)])
        u_out = np.stack([np.cos(theta + alpha), np.sin(theta + alpha)], axis=-1)  # (a, 2)
        q = np.zeros((alpha.size, t.size, 2))
        for k, (amp, times) in enumerate(imp):
            s = t[:, None] - times[None, :]                                   # (t, i)
            before = np.where(s < 0.0, s, 0.0) * u_in[k]                      # (t, i)
            after = np.where(s >= 0.0, s, 0.0)[None] * u_out[:, k][:, None, None]
            q[..., k] = np.sum(amp * (before[None] + after), axis=-1)
        d = np.minimum(_ray_distance(q, -u_in), _ray_distance(q, u_out[:, None, :]))
        out = np.maximum(out, d.max(axis=-1))
    return out if np.ndim(angle) else out.reshape(())


class ShapedCornerModel:
    """A planner corner model (``CornerModel``) that adds the shapers' corner cut to
    ``base``'s: ``V_node = tolerance / (tolerance / V_base + κ(α))``.

    Parameters
    ----------
    base : CornerModel
        The loop's corner model (e.g. ``SeedCornerModel``).
    shapers : sequence of 2 InputShaper or None
        The x and y shapers.
    """

    def __init__(self, base: CornerModel, shapers: Sequence[InputShaper | None]):
        self.base = base
        self.shapers = tuple(shapers)
        self._kappa = shaper_corner_error(self.shapers, _ANGLES)

    def relative_error(self, angle: float) -> float:
        """The shapers' κ(α) (s), interpolated on a 3° grid (κ is smooth in α)."""
        return float(np.interp(abs(angle), _ANGLES, self._kappa))

    def max_node_speed(self, angle: float, tolerance: float) -> float:
        """Largest node speed (m/s) keeping loop and shaper error within ``tolerance``."""
        v = self.base.max_node_speed(angle, tolerance)
        rel = (tolerance / v if math.isfinite(v) and v > 0.0 else
               (math.inf if v == 0.0 else 0.0)) + self.relative_error(angle)
        return tolerance / rel if rel > 0.0 else math.inf


def curve_acceleration(shapers: Sequence[InputShaper | None], tolerance: float,
                       share: float = SHAPER_SHARE) -> float:
    """The centripetal acceleration (m/s²) at which a curve through ``shapers`` shrinks by
    ``share·tolerance`` (m): ``2·share·tolerance/σ²`` with σ the larger axis' impulse
    spread (``InputShaper.spread``); ``inf`` without a shaper or with ``share`` 0."""
    spread = max((s.spread for s in shapers if s is not None), default=0.0)
    if spread <= 0.0 or share <= 0.0:
        return math.inf
    return 2.0 * share * tolerance / spread**2
