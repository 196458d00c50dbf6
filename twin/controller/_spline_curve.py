"""Arc-length machinery of a planar natural cubic spline (the engine of ``SplinePath``).

The curve is ``r(u) = (x(u), y(u))``, natural cubic splines of the cumulative chord length u.
Per piece k, with the local parameter ``t = u − u_k`` in ``[0, h_k]``:

* arc length ``L(t) = ∫ |r'(τ)| dτ`` by 8-node Gauss–Legendre on sub-intervals of each piece,
  halved until the rule and its two halves agree to 1e-13 relative (most pieces need none);
* ``s → (k, t)``: bisection on the sub-interval table, then safeguarded Newton on
  ``L(t) = σ`` (``L' = |r'|``, bracketed by the sub-interval) from a degree-9 polynomial
  fitted to the inverse ``t(σ)`` of each sub-interval at construction; the guess is good to
  ~1e-7 of the sub-interval, so one Newton step (one quadrature) reaches rounding;
* closest point: per candidate piece (pruned by its tight bounding box against the nearest
  knot), the squared distance ``D(τ)``, ``τ = t/h_k`` in [0, 1], is a sextic; its minimum is
  at an end or at a real root of ``D'``, a quintic solved by companion-matrix eigenvalues and
  polished by Newton.

Scalar queries use the ``math`` module on one row of coefficients (no array arithmetic) and reuse
the last ``s → (k, t)`` answer, because point, tangent and curvature are asked at one s.
"""

from __future__ import annotations

import math
from bisect import bisect_right

import numpy as np

from twin.controller.spline import natural_cubic

__all__ = ["SplineCurve"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_X, _GL_W = 0.5 * (_GL_X + 1.0), 0.5 * _GL_W  # on [0, 1]
_GL_PY = tuple(zip(_GL_X.tolist(), _GL_W.tolist(), strict=True))
_sqrt = math.sqrt  # norms as sqrt(x·x + y·y): the compiled path (cyclic.py) computes the same
_RTOL = 1e-13  # quadrature acceptance, relative
_MAX_LEVELS = 40  # sub-interval halvings (a cusp, |r'| = 0, would stop here)
_MAX_NEWTON = 60
_NEWTON_DONE = 1e-7  # after a step below this fraction of the sub-interval, error ≲ 1e-14 of it
_INV_DEGREE = 9  # initial guess of s → t good to ~1e-7, so one Newton step finishes
_INV_X = 0.5 * (1.0 - np.cos(np.pi * np.arange(_INV_DEGREE + 1) / _INV_DEGREE))
# S[i, m] = ∫_0^{X_i} ℓ_m, ℓ_m the Lagrange basis of the nodes X: integrates sampled values
_INV_S = (np.vander(_INV_X, _INV_X.size + 1, increasing=True)[:, 1:]
          / np.arange(1, _INV_X.size + 1)) @ np.linalg.inv(np.vander(_INV_X, increasing=True))
_PAIRS_PER_CHUNK = 1 << 18
_DROP = 1e-10  # relative size below which a quintic coefficient counts as zero


class SplineCurve:
    """Planar natural cubic spline through ``pts`` (n, 2) with arc-length queries.

    Attributes
    ----------
    knot_s : ndarray, shape (n,)
        Arc length at each point (m).
    box_lower, box_upper : ndarray, shape (n-1, 2)
        Tight bounding box of each piece (m).
    """

    def __init__(self, pts: np.ndarray, *, method: str):
        u = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))))
        sp = natural_cubic(u, pts, method=method)
        self._u = u
        self._pts = pts
        self._h = np.diff(u)
        self._a, self._b, self._c, self._d = sp.a, sp.b, sp.c, sp.d  # (K, 2) each
        self._rows = np.concatenate((sp.a, sp.b, sp.c, sp.d), axis=1)  # (K, 8) for scalar use
        self._rows_py = self._rows.tolist()
        self._velocity = (*sp.b.T, *(2.0 * sp.c.T), *(3.0 * sp.d.T))  # r' = b + 2c·t + 3d·t²
        self._subdivide()
        self._fit_inverse()
        self.box_lower, self.box_upper = self._boxes()
        self._last = (math.nan, (), 0.0)

    # -- arc length ----------------------------------------------------------------------
    def _speed(self, k, t):
        """``|r'(t)|`` on pieces k (arrays that broadcast)."""
        bx, by, cx, cy, dx, dy = (v[k] for v in self._velocity)
        return np.hypot(bx + t * (cx + t * dx), by + t * (cy + t * dy))

    def _integral(self, k, t0, t1):
        """``∫_{t0}^{t1} |r'|`` on piece k; arrays (P,)."""
        dt = t1 - t0
        tt = t0[:, None] + dt[:, None] * _GL_X
        return dt * (self._speed(k[:, None], tt) @ _GL_W)

    def _subdivide(self) -> None:
        k = np.arange(self._h.size)
        a, b = np.zeros(k.size), self._h.copy()
        parts = []
        for level in range(_MAX_LEVELS):
            mid = 0.5 * (a + b)
            whole = self._integral(k, a, b)
            halves = self._integral(k, a, mid) + self._integral(k, mid, b)
            ok = np.abs(whole - halves) <= _RTOL * halves
            if level == _MAX_LEVELS - 1:
                ok[:] = True
            parts.append((k[ok], a[ok], b[ok], halves[ok]))
            k, a, b, mid = k[~ok], a[~ok], b[~ok], mid[~ok]
            if not k.size:
                break
            k = np.repeat(k, 2)
            a, b = np.stack((a, mid), axis=1).ravel(), np.stack((mid, b), axis=1).ravel()
        k, a, b, length = (np.concatenate(p) for p in zip(*parts, strict=True))
        order = np.lexsort((a, k))
        k, a, b, length = k[order], a[order], b[order], length[order]
        s0 = np.concatenate(([0.0], np.cumsum(length)))
        self._first = np.searchsorted(k, np.arange(self._h.size + 1))
        self.knot_s = s0[self._first]
        self.knot_s.setflags(write=False)
        self._sub = (k, a, b, length)
        self._sub_s0 = s0[:-1]
        self._sub_u0 = self._u[k] + a
        self._s0_py = self._sub_s0.tolist()

    def _fit_inverse(self) -> None:
        """Per sub-interval, τ = (t − a)/(b − a) as a polynomial of x = σ/L (the initial guess
        of s → t): interpolate the pairs (σ(t_i)/L, τ_i) at Chebyshev–Lobatto τ_i, with σ(t_i)
        from the speed at the same nodes by spectral integration (a guess needs no more)."""
        k, a, b, length = self._sub
        w = b - a
        speed = self._speed(k[:, None], a[:, None] + w[:, None] * _INV_X)
        x = (speed @ _INV_S.T) * (w / length)[:, None]
        vander = x[:, :, None] ** np.arange(_INV_X.size)
        rhs = np.broadcast_to(_INV_X, x.shape)[..., None]
        self._inverse = np.linalg.solve(vander, rhs)[..., 0]  # (J, degree + 1), ascending
        self._table = np.column_stack((k, a, b, length, self._inverse))
        self._table_py = self._table.tolist()  # scalar path: no per-call conversion

    def _guess(self, j: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        a, b, length = self._sub[1][j], self._sub[2][j], self._sub[3][j]
        x = np.clip(sigma / length, 0.0, 1.0)
        return a + (b - a) * np.clip(_polyval(self._inverse[j], x[:, None])[:, 0], 0.0, 1.0)

    def _integral_py(self, row: list[float], t0: float, t1: float) -> float:
        """Scalar form of :meth:`_integral` for the piece with coefficient row ``row``."""
        _, _, bx, by, cx, cy, dx, dy = row
        cx, cy, dx, dy = 2.0 * cx, 2.0 * cy, 3.0 * dx, 3.0 * dy
        acc, dt = 0.0, t1 - t0
        for x, w in _GL_PY:
            t = t0 + dt * x
            ex, ey = bx + t * (cx + t * dx), by + t * (cy + t * dy)
            acc += w * _sqrt(ex * ex + ey * ey)
        return acc * dt

    def _locate(self, s: float) -> tuple[list[float], float]:
        """Coefficient row of the piece and local parameter at arc length s (scalar, cached)."""
        last_s, row, t = self._last
        if s == last_s:
            return row, t
        j = min(max(bisect_right(self._s0_py, s) - 1, 0), len(self._s0_py) - 1)
        k, a, b, length, *inverse = self._table_py[j]
        row = self._rows_py[int(k)]
        sigma = min(max(s - self._s0_py[j], 0.0), length)
        x = sigma / length
        tau = 0.0
        for c in reversed(inverse):
            tau = tau * x + c
        t = a + (b - a) * min(max(tau, 0.0), 1.0)
        lo, hi = a, b
        for _ in range(_MAX_NEWTON):
            f = self._integral_py(row, a, t) - sigma
            if f > 0.0:
                hi = t
            else:
                lo = t
            _, _, vx, vy, _, _ = _derivatives_py(row, t)
            v = _sqrt(vx * vx + vy * vy)
            new = t - f / v if v > 0.0 else 0.5 * (lo + hi)
            if not lo <= new <= hi:
                new = 0.5 * (lo + hi)
            done = abs(new - t) <= _NEWTON_DONE * (b - a)
            t = new
            if done:
                break
        self._last = (s, row, t)
        return row, t

    def _locate_many(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vector form of :meth:`_locate`."""
        j = np.clip(np.searchsorted(self._sub_s0, s, side="right") - 1, 0, self._sub_s0.size - 1)
        sigma = s - self._sub_s0[j]
        return self._sub[0][j], self._solve(j, sigma)

    def _solve(self, j: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        """Local parameter t where the arc length from the start of sub-interval j is sigma."""
        k, a, b, length = (v[j] for v in self._sub)
        sigma = np.clip(sigma, 0.0, length)
        t = self._guess(j, sigma)
        lo, hi = a.copy(), b.copy()
        todo = np.arange(sigma.size)
        for _ in range(_MAX_NEWTON):
            kk, tt = k[todo], t[todo]
            f = self._integral(kk, a[todo], tt) - sigma[todo]
            above = f > 0.0
            hi[todo] = np.where(above, tt, hi[todo])
            lo[todo] = np.where(above, lo[todo], tt)
            v = self._speed(kk, tt)
            with np.errstate(divide="ignore", invalid="ignore"):
                new = tt - f / v
            bad = ~((lo[todo] <= new) & (new <= hi[todo]))
            new[bad] = 0.5 * (lo[todo] + hi[todo])[bad]
            done = np.abs(new - tt) <= _NEWTON_DONE * (b[todo] - a[todo])
            t[todo] = new
            todo = todo[~done]
            if not todo.size:
                break
        return t

    def _s_of(self, k: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Arc length at piece k, local parameter t (arrays)."""
        j = np.searchsorted(self._sub_u0, self._u[k] + t, side="right") - 1
        j = np.clip(j, self._first[k], self._first[k + 1] - 1)
        a = self._sub[1][j]
        return self._sub_s0[j] + self._integral(k, a, np.maximum(t, a))

    # -- evaluation ----------------------------------------------------------------------
    def frame_at(self, s: float) -> tuple[float, float, float, float, float, float]:
        """x, y (m), unit tangent, curvature (1/m) and dκ/ds (1/m²) at arc length s (scalar,
        clipped by the caller)."""
        row, t = self._locate(s)
        x, y, vx, vy, ax, ay = _derivatives_py(row, t)
        speed = _sqrt(vx * vx + vy * vy)
        cross, dot = vx * ay - vy * ax, vx * ax + vy * ay
        cube = speed * speed * speed
        # κ = (r′ × r″)/|r′|³ and dκ/ds = (dκ/dt)/|r′|, with r‴ = 6·d
        rate = (vx * row[7] - vy * row[6]) * 6.0 / cube - 3.0 * cross * dot / (cube * (speed
                                                                                      * speed))
        return x, y, vx / speed, vy / speed, cross / cube, rate / speed

    def kernel_tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The scalar path's tables for the compiled tick (``cyclic.curve_frame``):
        sub-interval start arc lengths (J,), the table ``k, a, b, length, inverse
        coefficients`` (J, 4 + degree + 1) and the coefficient rows (K, 8)."""
        return self._sub_s0, self._table, self._rows

    def _derivatives(self, s: np.ndarray):
        k, t = self._locate_many(s)
        t = t[:, None]
        b, c, d = self._b[k], self._c[k], self._d[k]
        return k, t, b + t * (2.0 * c + t * (3.0 * d)), 2.0 * c + t * (6.0 * d)

    def points_at(self, s: np.ndarray) -> np.ndarray:
        """Points (n, 2) (m) at arc lengths s (n,)."""
        k, t = self._locate_many(s.ravel())
        t = t[:, None]
        out = self._a[k] + t * (self._b[k] + t * (self._c[k] + t * self._d[k]))
        return out.reshape((*s.shape, 2))

    def tangents_at(self, s: np.ndarray) -> np.ndarray:
        """Unit tangents (n, 2) at arc lengths s (n,)."""
        _, _, vel, _ = self._derivatives(s.ravel())
        return (vel / np.linalg.norm(vel, axis=1, keepdims=True)).reshape((*s.shape, 2))

    def curvatures_at(self, s: np.ndarray) -> np.ndarray:
        """Signed curvatures (n,) (1/m) at arc lengths s (n,)."""
        _, _, vel, acc = self._derivatives(s.ravel())
        cross = vel[:, 0] * acc[:, 1] - vel[:, 1] * acc[:, 0]
        return (cross / np.linalg.norm(vel, axis=1) ** 3).reshape(s.shape)

    # -- closest point -------------------------------------------------------------------
    def _scaled(self, k: np.ndarray) -> np.ndarray:
        """Coefficients in τ = t/h of the pieces k: shape (P, 4, 2)."""
        h = self._h[k][:, None]
        return np.stack((self._a[k], self._b[k] * h, self._c[k] * h**2, self._d[k] * h**3), 1)

    def _boxes(self) -> tuple[np.ndarray, np.ndarray]:
        co = self._scaled(np.arange(self._h.size))  # (K, 4, 2)
        qa, qb, qc = 3.0 * co[:, 3], 2.0 * co[:, 2], co[:, 1]  # x'(τ) = qa τ² + qb τ + qc
        with np.errstate(divide="ignore", invalid="ignore"):
            disc = np.sqrt(np.maximum(qb * qb - 4.0 * qa * qc, 0.0))
            q = -0.5 * (qb + np.copysign(disc, qb))
            roots = np.stack((np.zeros_like(qa), np.ones_like(qa), q / qa, qc / q), axis=1)
        tau = np.clip(np.nan_to_num(roots, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
        c0, c1, c2, c3 = (co[:, None, i] for i in range(4))
        vals = c0 + tau * (c1 + tau * (c2 + tau * c3))
        return vals.min(axis=1), vals.max(axis=1)

    def closest(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arc length of the closest point and the distance (m) for points (Q, 2)."""
        s = np.empty(len(pts))
        dist = np.empty(len(pts))
        rows = max(1, _PAIRS_PER_CHUNK // len(self.knot_s))
        for i in range(0, len(pts), rows):
            s[i:i + rows], dist[i:i + rows] = self._closest_chunk(pts[i:i + rows])
        return s, dist

    def _closest_chunk(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        knots = self._pts
        to_knot = np.hypot(pts[:, None, 0] - knots[:, 0], pts[:, None, 1] - knots[:, 1])
        best_knot = to_knot.argmin(axis=1)
        best = to_knot[np.arange(len(pts)), best_knot] ** 2
        s = self.knot_s[best_knot].copy()
        gap = np.maximum(np.maximum(self.box_lower - pts[:, None], pts[:, None] - self.box_upper),
                         0.0)
        qi, ki = np.nonzero((gap**2).sum(axis=2) < best[:, None])
        if qi.size:
            co = self._scaled(ki)
            co[:, 0] -= pts[qi]
            tau, d2 = _minimise_sextic(co[..., 0], co[..., 1])
            order = np.lexsort((d2, qi))
            first = order[np.r_[True, qi[order][1:] != qi[order][:-1]]]
            q, better = qi[first], d2[first] < best[qi[first]]
            q, win = q[better], first[better]
            best[q] = d2[win]
            s[q] = self._s_of(ki[win], tau[win] * self._h[ki[win]])
        return s, np.sqrt(best)


def _derivatives_py(row: list[float], t: float) -> tuple[float, ...]:
    """x, y, x', y', x'', y'' of the piece with coefficient row (a, b, c, d per axis) at t."""
    ax, ay, bx, by, cx, cy, dx, dy = row
    return (ax + t * (bx + t * (cx + t * dx)), ay + t * (by + t * (cy + t * dy)),
            bx + t * (2.0 * cx + 3.0 * t * dx), by + t * (2.0 * cy + 3.0 * t * dy),
            2.0 * cx + 6.0 * t * dx, 2.0 * cy + 6.0 * t * dy)


def _polyval(coef: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Rows of ascending coefficients (P, m) at tau (P, C)."""
    out = np.broadcast_to(coef[:, -1:], tau.shape).copy()
    for i in range(coef.shape[1] - 2, -1, -1):
        out = out * tau + coef[:, i:i + 1]
    return out


def _minimise_sextic(cx: np.ndarray, cy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Minimum over τ in [0, 1] of ``X(τ)² + Y(τ)²`` for cubics X, Y (P, 4) (ascending).

    Candidates: both ends and every root of ``E = (X·X' + Y·Y')`` (the quintic D'/2) from the
    companion matrix, real parts clipped to [0, 1] (a generous candidate only costs an
    evaluation), each also polished by three Newton steps on E.
    """
    e = np.zeros((len(cx), 6))
    for c in (cx, cy):
        dc = c[:, 1:] * np.array([1.0, 2.0, 3.0])
        for i in range(4):
            e[:, i:i + 3] += c[:, i:i + 1] * dc
    de = e[:, 1:] * np.arange(1.0, 6.0)
    tau = np.concatenate((np.zeros((len(e), 1)), np.ones((len(e), 1)), _root_real_parts(e)), 1)
    tau = np.clip(tau, 0.0, 1.0)
    polished = tau.copy()
    for _ in range(3):
        slope = _polyval(de, polished)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(slope != 0.0, _polyval(e, polished) / slope, 0.0)
        polished = np.clip(polished - np.nan_to_num(step), 0.0, 1.0)
    tau = np.concatenate((tau, polished), axis=1)
    d2 = _polyval(cx, tau) ** 2 + _polyval(cy, tau) ** 2
    i = d2.argmin(axis=1)
    rows = np.arange(len(tau))
    return tau[rows, i], d2[rows, i]


def _root_real_parts(e: np.ndarray) -> np.ndarray:
    """Real parts of the roots of the quintics ``e`` (P, 6); unused slots hold 0."""
    scale = np.abs(e).max(axis=1, keepdims=True)
    en = e / np.where(scale > 0.0, scale, 1.0)
    degree = 5 - np.argmax((np.abs(en) > _DROP)[:, ::-1], axis=1)
    out = np.zeros((len(e), 5))
    for m in range(1, 6):
        sel = np.flatnonzero(degree == m)
        if not sel.size:
            continue
        comp = np.zeros((sel.size, m, m))
        comp[:, np.arange(1, m), np.arange(m - 1)] = 1.0
        comp[:, :, -1] = -en[sel, :m] / en[sel, m:m + 1]
        out[sel, :m] = np.linalg.eigvals(comp).real
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)
