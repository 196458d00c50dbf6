"""Exact solutions of the drive's linear pieces between two events (numba, scalar).

Between firing instants the converter's mean voltage u is constant and the rotor speed is
taken linear in time (ω(t) = ω0 + ω'·t, extrapolated by the caller), so the back-EMF is
E(t) = E0 + E1·t and the armature equation

    L·di/dt = u − E0 − E1·t − R·i        (− U_v in the conducting sense: a constant drop)

has the closed-form solution i(t) = A + B·t + (i0 − A)·e^{−t/T_a} with B = −E1/R,
A = (u − E0 + E1·T_a)/R. A thyristor bridge conducts in one sense only: the first zero of
i(t) (found by a bracketed Newton iteration — i(t) is convex or concave, so the first root is
bracketed in closed form) ends conduction, and a non-conducting bridge starts when its
driving voltage u − E(t) turns positive in its sense. First-order filters with a ramp input
have closed forms as well (:func:`first_order`).
"""

from __future__ import annotations

import math

import numba

__all__ = ["armature_segment", "first_order"]


@numba.njit(cache=True)
def _current(j0, a, b, t_a, t):
    return a + b * t + (j0 - a) * math.exp(-t / t_a)


@numba.njit(cache=True)
def _charge(j0, a, b, t_a, t):
    return a * t + 0.5 * b * t * t + (j0 - a) * t_a * -math.expm1(-t / t_a)


@numba.njit(cache=True)
def _extinction(j0, a, b, t_a, h):
    """First t in (0, h] with j(t) = a + b·t + (j0 − a)·e^{−t/T_a} = 0, or −1 if none.

    j0 >= 0, and j > 0 just after 0. j'' = (j0 − a)/T_a²·e^{−t/T_a} has one sign: a convex
    j can only cross before its minimum, a concave j crosses iff j(h) <= 0.
    """
    c = j0 - a
    if c >= 0.0:
        t_hi = h
        if b > 0.0:
            if c <= b * t_a:  # increasing from the start
                return -1.0
            t_hi = min(t_a * math.log(c / (b * t_a)), h)
        t = 0.0  # Newton from the left is monotone on a convex decreasing branch
    else:
        t_hi = h
        t = h  # and from the right on a concave one
    if _current(j0, a, b, t_a, t_hi) > 0.0:
        return -1.0
    lo, hi = 0.0, t_hi
    for _ in range(100):
        f = _current(j0, a, b, t_a, t)
        if f > 0.0:
            lo = t
        else:
            hi = t
        df = b - c / t_a * math.exp(-t / t_a)
        t_new = t - f / df if df != 0.0 else 0.5 * (lo + hi)
        if not lo <= t_new <= hi:
            t_new = 0.5 * (lo + hi)
        if abs(t_new - t) <= 1e-15 * (t_a + t):
            return t_new
        t = t_new
    return hi


@numba.njit(cache=True)
def armature_segment(i0, u, emf0, emf_slope, resistance, t_a, h, direction, drop=0.0):
    """Armature current over [0, h] with constant voltage and linearly varying EMF.

    Parameters
    ----------
    i0 : float
        Current at the start (A).
    u : float
        Converter mean voltage (V).
    emf0 : float
        Back-EMF at the start (V).
    emf_slope : float
        dE/dt over the segment (V/s).
    resistance : float
        R (Ω).
    t_a : float
        L/R (s), > 0.
    h : float
        Segment length (s), >= 0.
    direction : float
        +1 / −1: the converter conducts only in that sense (thyristor bridge; the current
        stops at zero and restarts when the driving voltage allows); 0: either sense (PWM).
    drop : float, optional
        Constant voltage drop against the current while it flows (V; brushes and
        thyristor thresholds); only with direction ±1.

    Returns
    -------
    i1 : float
        Current at the end (A), exactly 0.0 after an extinction.
    charge : float
        ∫ i dt over the segment (A·s).
    """
    s = -1.0 if direction < 0.0 else 1.0
    j0 = s * i0
    g0 = s * (u - emf0) - drop  # driving voltage in the conducting sense: g0 + g1·t
    g1 = -s * emf_slope
    t_on = 0.0
    if direction != 0.0 and j0 <= 0.0:
        j0 = 0.0
        if g0 <= 0.0:
            if g1 <= 0.0 or g0 + g1 * h <= 0.0:
                return 0.0, 0.0
            t_on = -g0 / g1  # the balance tips inside the segment
            g0 = 0.0
    span = h - t_on
    b = g1 / resistance
    a = (g0 - g1 * t_a) / resistance
    if direction != 0.0:
        t_z = _extinction(j0, a, b, t_a, span)
        if t_z >= 0.0:
            return 0.0, s * _charge(j0, a, b, t_a, t_z)
    return s * _current(j0, a, b, t_a, span), s * _charge(j0, a, b, t_a, span)


@numba.njit(cache=True)
def first_order(y, x0, slope, h, tau):
    """Exact step of tau·dy/dt = x0 + slope·t − y over [0, h] (tau = 0: y follows x)."""
    x1 = x0 + slope * h
    if tau <= 0.0:
        return x1
    lag = slope * tau
    return x1 - lag + (y - x0 + lag) * math.exp(-h / tau)
