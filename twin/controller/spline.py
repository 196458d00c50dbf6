"""Natural cubic spline through points (seed 000, eq. 1), with two exact coefficient solvers.

On each interval ``[x_k, x_{k+1}]`` the spline is

    g_k(x) = a_k + b_k·(x − x_k) + c_k·(x − x_k)² + d_k·(x − x_k)³,

twice continuously differentiable, with ``g''(x_0) = g''(x_{n-1}) = 0`` (the natural end
conditions). The seed expands each piece about its right knot; we expand about the left one
(as ``scipy.interpolate.CubicSpline`` does), which is the same function.

The only coupled part is the system for the knot second derivatives ``M_k = g''(x_k)``:

    h_{k-1}·M_{k-1} + 2·(h_{k-1} + h_k)·M_k + h_k·M_{k+1} = 6·(δ_k − δ_{k-1}),   k = 1 … n−2,

with ``h_k = x_{k+1} − x_k``, ``δ_k = (y_{k+1} − y_k)/h_k`` and ``M_0 = M_{n-1} = 0``: symmetric,
strictly diagonally dominant, tridiagonal. Two exact solvers are offered (``method``):

``"tridiagonal"``
    The classic forward/backward sweep (Thomas algorithm), run by LAPACK ``dgtsv``: for a
    strictly diagonally dominant matrix its partial pivoting never swaps rows, so it *is* the
    sweep, in compiled code. About 8 flops per unknown, strictly sequential.
``"blocks4"``
    The seed's idea (its ref. [4]: split the points into groups of four and write the
    coefficients in closed form, with no sweep) made exact. See :func:`solve_blocks4`.

Both give the same spline to rounding (~1e-13 relative); tests compare both against
``scipy.interpolate.CubicSpline(bc_type="natural")``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

__all__ = ["METHODS", "NaturalCubic", "natural_cubic", "solve_blocks4", "solve_tridiagonal"]

METHODS = ("tridiagonal", "blocks4")
"""Names accepted by ``natural_cubic(..., method=)``."""


@dataclass(frozen=True, slots=True)
class NaturalCubic:
    """A natural cubic spline ``y(x)``; call it to evaluate.

    Attributes
    ----------
    x : ndarray, shape (n,)
        Knots, strictly increasing.
    a, b, c, d : ndarray, shape (n-1,) or (n-1, m)
        Coefficients of ``g_k(x) = a + b·(x−x_k) + c·(x−x_k)² + d·(x−x_k)³`` on interval k
        (trailing axis when ``y`` had one: m curves sharing the knots).
    """

    x: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray

    def __call__(self, xq, nu: int = 0) -> np.ndarray:
        """Value or ``nu``-th derivative at ``xq``.

        Parameters
        ----------
        xq : float or array_like, shape (q,)
            Evaluation points, same unit as ``x``. Outside ``[x_0, x_{n-1}]`` the end pieces
            are extended (as scipy does).
        nu : int
            Derivative order, 0 … 3.

        Returns
        -------
        ndarray, shape ``xq.shape + y.shape[1:]``
        """
        if nu not in (0, 1, 2, 3):
            raise ValueError(f"nu must be 0, 1, 2 or 3, got {nu!r}")
        xq = np.asarray(xq, dtype=float)
        k = self.interval(xq)
        t = (xq - self.x[k]).reshape(xq.shape + (1,) * (self.a.ndim - 1))
        a, b, c, d = self.a[k], self.b[k], self.c[k], self.d[k]
        if nu == 0:
            return a + t * (b + t * (c + t * d))
        if nu == 1:
            return b + t * (2.0 * c + t * (3.0 * d))
        if nu == 2:
            return 2.0 * c + t * (6.0 * d)
        return 6.0 * d + 0.0 * t

    def interval(self, xq) -> np.ndarray:
        """Index k of the piece used at ``xq`` (``x_k ≤ xq < x_{k+1}``, clipped to the ends)."""
        k = np.searchsorted(self.x, xq, side="right") - 1
        return np.clip(k, 0, self.x.size - 2)


def natural_cubic(x, y, *, method: str = "tridiagonal") -> NaturalCubic:
    """Natural cubic spline through ``(x_k, y_k)``.

    Parameters
    ----------
    x : array_like, shape (n,)
        Knots, strictly increasing, finite, n ≥ 2 (two points give the straight line).
    y : array_like, shape (n,) or (n, m)
        Values; with a second axis, m splines sharing the knots are built with one solve.
    method : {"tridiagonal", "blocks4"}
        Solver for the knot second derivatives (see the module docstring).

    Returns
    -------
    NaturalCubic

    Raises
    ------
    ValueError
        Naming what is wrong: too few points, shapes, non-finite values, x not increasing,
        unknown method.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    x, y = _validated(x, y)
    h = np.diff(x)
    delta = np.diff(y, axis=0) / _column(h, y)
    n = x.size
    second = np.zeros_like(y)
    if n > 2:
        rhs = 6.0 * np.diff(delta, axis=0)
        diag = 2.0 * (h[:-1] + h[1:])
        off = h[1:-1]
        solve = solve_tridiagonal if method == "tridiagonal" else solve_blocks4
        second[1:-1] = solve(off, diag, off, rhs)
    hc = _column(h, y)
    a = y[:-1].copy()
    b = delta - hc * (2.0 * second[:-1] + second[1:]) / 6.0
    c = 0.5 * second[:-1]
    d = (second[1:] - second[:-1]) / (6.0 * hc)
    for arr in (x, a, b, c, d):
        arr.setflags(write=False)
    return NaturalCubic(x, a, b, c, d)


def solve_tridiagonal(sub, diag, sup, rhs) -> np.ndarray:
    """Solve a tridiagonal system by the sweep (LAPACK ``dgtsv``).

    Parameters
    ----------
    sub, sup : ndarray, shape (N-1,)
        Sub- and super-diagonal.
    diag : ndarray, shape (N,)
        Main diagonal.
    rhs : ndarray, shape (N,) or (N, m)

    Returns
    -------
    ndarray, same shape as ``rhs``
    """
    rhs = np.asarray(rhs, dtype=float)
    b2 = rhs.reshape(rhs.shape[0], -1)
    if b2.shape[0] == 1:  # f2py rejects the empty off-diagonals
        return rhs / diag[0]
    *_, sol, info = lapack.dgtsv(sub, diag, sup, b2)
    if info != 0:
        raise np.linalg.LinAlgError(f"dgtsv: singular tridiagonal matrix (info = {info})")
    return sol.reshape(rhs.shape)


def solve_blocks4(sub, diag, sup, rhs) -> np.ndarray:
    """Solve a diagonally dominant tridiagonal system in blocks of four, without a sweep.

    The unknowns are grouped as ``[4 block unknowns, 1 separator]`` repeated: rows
    ``5j … 5j+3`` form block j, row ``5j+4`` is separator j (the system is padded with
    identity rows to length ``5m+4``). Given its two neighbouring separators ``z_L`` and
    ``z_R``, a block is a 4×4 tridiagonal system solved in closed form:

        β_0 = b_0,  l_i = a_i/β_{i-1},  β_i = b_i − l_i·c_{i-1}        (i = 1, 2, 3)
        z_block = p + z_L·q + z_R·w

    where ``p = T⁻¹r``, ``q = −a_0·T⁻¹e_0`` and ``w = −c_3·T⁻¹e_3`` are written out with those
    three pivots (``β_i`` are ratios of the block's continuants θ_{i+1}/θ_i). All blocks are
    eliminated at once (vector operations over the blocks). Substituting the block solutions
    into the separator rows gives a tridiagonal system five times smaller,

        a_s·q_3^(j)·z_{j-1} + (b_s + a_s·w_3^(j) + c_s·q_0^(j+1))·z_j + c_s·w_0^(j+1)·z_{j+1}
            = r_s − a_s·p_3^(j) − c_s·p_0^(j+1),

    which is solved the same way, recursively, until one block is left; then the blocks are
    recovered from their separators. It is block Gaussian elimination in a different order,
    so it is exact (no approximation); the Schur complements of a strictly diagonally
    dominant matrix stay strictly diagonally dominant, so no pivoting is needed.

    Cost: per block of five unknowns about 40 flops for the matrix (4 reciprocals, pivots,
    q, w, reduced row) and 36 per right-hand side (p, reduced right side, recovery), i.e. ~15
    flops per unknown for one right-hand side; the levels shrink by 5, so the total is 1.25×
    that, ~19 flops per unknown against ~8 for the sweep, but done in ``log5(N)``
    data-parallel stages of ~70 array operations instead of N dependent steps. In numpy the
    compiled sweep stays faster (``bench/spline.py``); the method pays off where the stages
    run in parallel hardware, or where no compiled sweep is at hand.

    Parameters and result as for :func:`solve_tridiagonal`.
    """
    rhs = np.asarray(rhs, dtype=float)
    n = rhs.shape[0]
    lower = np.concatenate(([0.0], sub))
    upper = np.concatenate((sup, [0.0]))
    sol = _blocks4(lower, np.asarray(diag, dtype=float), upper, rhs.reshape(n, -1))
    return sol.reshape(rhs.shape)


def _blocks4(a: np.ndarray, b: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """One level of :func:`solve_blocks4`; ``a[0] = c[-1] = 0``, ``r`` shape (N, m)."""
    n, m = r.shape
    nsep = max(0, -(-(n - 4) // 5))
    nblk = nsep + 1
    size = 5 * nblk  # one padding row more than 5·nsep + 4, so that rows reshape to (nblk, 5)
    pad = size - n
    a = np.concatenate((a, np.zeros(pad))).reshape(nblk, 5)
    b = np.concatenate((b, np.ones(pad))).reshape(nblk, 5)
    c = np.concatenate((c, np.zeros(pad))).reshape(nblk, 5)
    r = np.concatenate((r, np.zeros((pad, m)))).reshape(nblk, 5, m)

    # closed-form elimination of the 4×4 blocks (vectorised over blocks)
    a0, a1, a2, a3 = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    c0, c1, c2, c3 = c[:, 0], c[:, 1], c[:, 2], c[:, 3]
    i0 = 1.0 / b[:, 0]
    l1 = a1 * i0
    i1 = 1.0 / (b[:, 1] - l1 * c0)
    l2 = a2 * i1
    i2 = 1.0 / (b[:, 2] - l2 * c1)
    l3 = a3 * i2
    i3 = 1.0 / (b[:, 3] - l3 * c2)
    p = np.empty((nblk, 4, m))
    g1 = r[:, 1] - l1[:, None] * r[:, 0]
    g2 = r[:, 2] - l2[:, None] * g1
    p[:, 3] = (r[:, 3] - l3[:, None] * g2) * i3[:, None]
    p[:, 2] = (g2 - c2[:, None] * p[:, 3]) * i2[:, None]
    p[:, 1] = (g1 - c1[:, None] * p[:, 2]) * i1[:, None]
    p[:, 0] = (r[:, 0] - c0[:, None] * p[:, 1]) * i0[:, None]
    q = np.empty((nblk, 4))  # response to the left separator: rhs −a_0·e_0
    q1g = l1 * a0
    q2g = -l2 * q1g
    q[:, 3] = -l3 * q2g * i3
    q[:, 2] = (q2g - c2 * q[:, 3]) * i2
    q[:, 1] = (q1g - c1 * q[:, 2]) * i1
    q[:, 0] = (-a0 - c0 * q[:, 1]) * i0
    w = np.empty((nblk, 4))  # response to the right separator: rhs −c_3·e_3
    w[:, 3] = -c3 * i3
    w[:, 2] = -c2 * w[:, 3] * i2
    w[:, 1] = -c1 * w[:, 2] * i1
    w[:, 0] = -c0 * w[:, 1] * i0

    sep = np.zeros((nblk + 1, m))  # separator values, with z_L = z_R = 0 at both ends
    if nsep:
        a_s, b_s, c_s = a[:-1, 4], b[:-1, 4], c[:-1, 4]
        red_a = a_s * q[:-1, 3]
        red_b = b_s + a_s * w[:-1, 3] + c_s * q[1:, 0]
        red_c = c_s * w[1:, 0]
        red_r = r[:-1, 4] - a_s[:, None] * p[:-1, 3] - c_s[:, None] * p[1:, 0]
        red_a[0] = 0.0
        red_c[-1] = 0.0
        sep[1:-1] = _blocks4(red_a, red_b, red_c, red_r)
    out = np.empty((nblk, 5, m))
    out[:, :4] = p + q[:, :, None] * sep[:-1, None, :] + w[:, :, None] * sep[1:, None, :]
    out[:, 4] = sep[1:]
    return out.reshape(size, m)[:n]


def _column(v: np.ndarray, like: np.ndarray) -> np.ndarray:
    """``v`` (k,) shaped to broadcast against ``like`` (k, ...)."""
    return v.reshape(v.shape + (1,) * (like.ndim - 1))


def _validated(x, y) -> tuple[np.ndarray, np.ndarray]:
    x = np.array(x, dtype=float)
    y = np.array(y, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"x must be one-dimensional, got shape {x.shape}")
    if x.size < 2:
        raise ValueError(f"need at least 2 points, got {x.size}")
    if y.ndim not in (1, 2) or y.shape[0] != x.size:
        raise ValueError(f"y must have shape ({x.size},) or ({x.size}, m), got {y.shape}")
    for name, arr in (("x", x), ("y", y)):
        bad = np.flatnonzero(~np.isfinite(arr.reshape(x.size, -1)).all(axis=1))
        if bad.size:
            k = bad[0]
            raise ValueError(f"{name}[{k}] is not finite: {arr[k].tolist()}")
    step = np.diff(x)
    bad = np.flatnonzero(~(step > 0.0))
    if bad.size:
        k = bad[0] + 1
        raise ValueError(
            f"x must be strictly increasing: x[{k}] = {float(x[k])!r} ≤ x[{k - 1}] = "
            f"{float(x[k - 1])!r}")
    return x, y
