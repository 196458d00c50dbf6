"""The digital correcting device (DCU, seed 000 "ЦКУ") and the equivalent feed-forward gains.

The DCU acts on the position reference and its output is added to the position regulator's
output (seed 000, Fig. 10)::

    D(z) = α1·∇ + α2·∇² + α3·∇³,   ∇ = 1 - z^-1,
    u = W_rp(z)·e + D(z)·x_ref,    e = x_ref - x,    x = G(z)·u

so the error transfer function is ``Φ_e(z) = (1 - G·D) / (1 + G·W_rp)``. Expanded in powers of
``w = ∇``, ``Φ_e = c0 + c1·w + c2·w² + …`` and, once the transient has died out, the error of
the sampled loop is ``e = c0·x_ref + c1·∇x_ref + c2·∇²x_ref + …``: the error coefficients
``C0 … C3`` of seed 000 (eq. 3) are these ``c_k`` (the seed writes them against derivatives,
which is a triangular change of basis, so ``C0..Ck = 0 ⇔ c0..ck = 0``).

With ``H(w) = w·G`` (analytic at ``w = 0`` thanks to the free integrator, ``H(0) = K_H·T``)
the numerator is ``w·(1 - H·(α1 + α2·w + α3·w²))``: ``c0 = 0`` for any ``α`` (type-1 loop) and
the order-k DCU makes ``c1 … ck`` vanish by solving the lower-triangular Toeplitz system
``H(w)·(α1 + α2·w + …) = 1 + O(w^k)``. Its first row gives seed 000's closed form
``α1 = 1/(K_H·T)``. The solution does not depend on the regulator ``W_rp``: the DCU is the
series inverse of the sampled plant (ZOH and computation delay included), which is what
absolute invariance to the reference requires.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg

from twin.controller.linear import LinearAxisModel, power_series_ratio
from twin.errors import ConfigError

__all__ = [
    "dcu_as_feedforward",
    "dcu_coefficients",
    "error_coefficients",
    "feedforward_gains",
]

MAX_ORDER = 3


def _in_w(coefficients: np.ndarray) -> np.ndarray:
    """Ascending polynomial in ``z^-1`` rewritten in ``w = 1 - z^-1`` (ascending)."""
    poly = np.polynomial.Polynomial(coefficients)
    return poly(np.polynomial.Polynomial([1.0, -1.0])).coef


def _h_series(model: LinearAxisModel, period: float, count: int,
              delay_ticks: int) -> np.ndarray:
    """Taylor coefficients of ``H(w) = w·G`` at ``w = 0``, the first one ``K_H·T``."""
    b, q = model.discrete_increments(period, delay_ticks=delay_ticks)
    return power_series_ratio(_in_w(b), _in_w(q), count)


def _check_order(order: int) -> None:
    if isinstance(order, bool) or not isinstance(order, int | np.integer) \
            or not 0 <= order <= MAX_ORDER:
        raise ConfigError("order", f"must be an integer 0…{MAX_ORDER}, got {order!r}")


def dcu_coefficients(model: LinearAxisModel, period: float, order: int, *,
                     delay_ticks: int = 1) -> np.ndarray:
    """DCU coefficients ``α1, α2, α3`` that make ``C0 … C_order`` vanish.

    Parameters
    ----------
    model : LinearAxisModel
        Reference (V) → position (m) model of the axis.
    period : float
        Position-loop period ``T`` (s).
    order : int
        0 … 3; coefficients beyond ``order`` are zero (order 0: no DCU).
    delay_ticks : int
        Computation delay (periods) of the loop, 1 for the classic sample → compute →
        write-at-next-tick controller.

    Returns
    -------
    ndarray, shape (3,)
        ``(α1, α2, α3)`` (V/m): with ``D(z)`` applied to the reference in metres the DCU
        output is in volts.
    """
    _check_order(order)
    alpha = np.zeros(MAX_ORDER)
    if order == 0:
        return alpha
    h = _h_series(model, period, order, delay_ticks)
    # H(w)·(α1 + α2·w + α3·w²) = 1 + O(w^order): lower-triangular Toeplitz in h.
    toeplitz = scipy.linalg.toeplitz(h, np.zeros(order))
    rhs = np.zeros(order)
    rhs[0] = 1.0
    alpha[:order] = scipy.linalg.solve_triangular(toeplitz, rhs, lower=True)
    return alpha


def error_coefficients(model: LinearAxisModel, period: float,
                       alpha: Sequence[float] = (0.0, 0.0, 0.0), *, kp: float,
                       ki: float = 0.0, kd: float = 0.0, count: int = 4,
                       delay_ticks: int = 1) -> np.ndarray:
    """Error coefficients ``c0 … c_{count-1}`` of the sampled loop, ``Φ_e`` in powers of ∇.

    The regulator is seed 004's ``W_rp = kp + kd·∇/T + ki·T/∇`` (the one of
    ``PositionRegulator``); ``alpha`` the DCU. In steady state
    ``e = Σ c_k·∇^k x_ref`` (m), so a polynomial reference of degree n leaves the error
    ``c_n·∇^n x_ref`` when ``c0 … c_{n-1} = 0``.

    Parameters
    ----------
    model : LinearAxisModel
        The axis.
    period : float
        Loop period ``T`` (s).
    alpha : sequence of 3 float
        DCU coefficients (V/m).
    kp, ki, kd : float
        Regulator gains (V/m, V/(m·s), V·s/m); ``kp`` or ``ki`` must be positive.
    count : int
        Number of coefficients.
    delay_ticks : int
        Computation delay (periods).

    Returns
    -------
    ndarray, shape (count,)
        ``c_k`` (dimensionless: metres of error per metre of ``∇^k x_ref``).
    """
    a = np.asarray(alpha, dtype=float)
    if a.shape != (MAX_ORDER,) or not np.all(np.isfinite(a)):
        raise ConfigError("alpha", f"must be 3 finite numbers, got {alpha!r}")
    if not (kp > 0.0 or ki > 0.0):
        raise ConfigError("kp", "kp or ki must be > 0: without them the loop is open")
    n = count + 2
    h = _h_series(model, period, n, delay_ticks)
    w2 = np.zeros(n)
    w2[2] = 1.0
    # Φ_e·w²/w² = (w² - H·(α1w² + α2w³ + α3w⁴)) / (w² + H·(ki·T + kp·w + kd/T·w²))
    num = w2 - np.convolve(h, np.concatenate([[0.0, 0.0], a]))[:n]
    den = w2 + np.convolve(h, [ki * period, kp, kd / period])[:n]
    shift = 0 if ki > 0.0 else 1        # ki = 0: both have the factor w exactly
    return power_series_ratio(num[shift:], den[shift:], count)


def dcu_as_feedforward(alpha: Sequence[float] | np.ndarray, period: float) -> np.ndarray:
    """Feed-forward gains ``FF1, FF2, FF3`` that equal the DCU on the float channels.

    For a reference that is a cubic in time (over the last three periods) the backward
    differences are exactly ``∇x = T·v - T²·a/2 + T³·j/6``, ``∇²x = T²·a - T³·j`` and
    ``∇³x = T³·j`` (v, a, j at the current tick), so
    ``D(z)·x_ref = FF1·v_ref + FF2·a_ref + FF3·j_ref`` with the gains returned.

    Parameters
    ----------
    alpha : array_like, shape (..., 3)
        DCU coefficients (V/m), per axis along the leading dimensions.
    period : float
        Loop period ``T`` (s).

    Returns
    -------
    ndarray, shape (..., 3)
        ``FF1`` (V·s/m), ``FF2`` (V·s²/m), ``FF3`` (V·s³/m).
    """
    a = np.asarray(alpha, dtype=float)
    if a.shape[-1:] != (MAX_ORDER,):
        raise ConfigError("alpha", f"trailing dimension must be 3, got shape {a.shape}")
    t = float(period)
    a1, a2, a3 = a[..., 0], a[..., 1], a[..., 2]
    return np.stack([a1 * t, (a2 - 0.5 * a1) * t**2, (a1 / 6.0 - a2 + a3) * t**3], axis=-1)


def feedforward_gains(model: LinearAxisModel) -> np.ndarray:
    """Continuous ideal-inverse feed-forward gains of ``W0``.

    For ``W0 = K_H / (p·Q(p))`` with ``Q(0) = 1``, ``Q = 1 + q1·p + q2·p² + …`` the inverse
    ``p·Q(p)/K_H`` gives ``FF1 = 1/K_H``, ``FF2 = q1/K_H``, ``FF3 = q2/K_H`` (a numerator in
    ``W0`` is divided out as a series). These ignore the sampling: the ZOH (T/2) and the
    computation delay are not compensated; ``dcu_as_feedforward(dcu_coefficients(...))``
    gives the gains that are exact for the sampled loop.

    Returns
    -------
    ndarray, shape (3,)
        ``FF1`` (V·s/m), ``FF2`` (V·s²/m), ``FF3`` (V·s³/m).
    """
    return model.inverse_series(MAX_ORDER)
