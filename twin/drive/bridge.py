"""The pulse-level converter circuit between two events (numba, scalar).

A line-commutated converter applies to the armature, while a pair of thyristors conducts,
the instantaneous supply voltage of that pair: a sinusoid of the mains. Between two events
(a firing, the current reaching zero, the end of a commutation, the end of a drive
interval) the armature equation in the conducting sense of the bridge, j = b·i ≥ 0,

    L·dj/dt = v_c·cos(w·t) + v_s·sin(w·t) + g0 + g1·t − R·j        (t from the segment start)

(the pair's voltage as a phasor at the segment start, and the back-EMF −b·E(t), linear in
time because the caller extrapolates the rotor speed linearly) has the closed form

    j(t) = P(t) + (j0 − P(0))·e^{−t/τ},   P(t) = p_c·cos(w·t) + p_s·sin(w·t) + A + B·t,

with τ = L/R, B = g1/R, A = (g0 − g1·τ)/R and (p_c, p_s) the sinusoidal steady state of
the R-L branch (:func:`current_coeffs`). The charge ∫j dt has a closed form too
(:func:`charge`).

Device and brush drops enter this form exactly: the constant drop U_v (the brushes and the
threshold voltages of the thyristors in series) adds −U_v to g0, the thyristors' slope
resistances add to R (``current_coeffs`` is given the circuit's R_eff = R + n_d·r_T), and
a smoothing reactor adds to L.

Events are the *first* zero of such a function after the segment start, which a bracketing
method cannot promise (the current can dip to zero and recover between two samples).
:func:`first_root` steps with a curvature bound instead: from t with F(t) > 0 and a bound
M ≥ |F''| on [t, ∞) (closed form for every function here), F stays positive up to the first
zero of the parabola F + F'·s − M·s²/2, so the step to that zero can never jump over a root
of F. Near a simple root the step is Newton's (from the safe side), so it converges
quadratically; far from one it takes long steps. Three functions are searched:

- ``KIND_CURRENT``: the armature current j(t) less a threshold (extinction: the thyristors
  block at zero, or below the holding current once their gate pulse has ended; the caller
  shifts j0 and A by the threshold);
- ``KIND_RISE``: the negated current −j(t) less a threshold (latching: the first instant the
  current reaches the latching current);
- ``KIND_IGNITION``: −g(t), the negated driving voltage of a non-conducting pair whose gate
  pulse is on (conduction starts where g turns positive);
- ``KIND_COMMUTATION``: the end of a commutation overlap through the line inductance L_c,
  where the incoming thyristor has taken the whole current:
  ∫(u_in − u_out) dt / (2·L_c) = (j(t) + J0)/2, J0 the current when the overlap began;
- ``KIND_COMMUTATION_R``: the same with the thyristors' slope resistance r_T. The two
  branches of the commutating group share j, and their difference Δ = i_in − i_out obeys
  L_c·dΔ/dt + r_T·Δ = u_in − u_out, so Δ(t) = q_c·cos(w·t) + q_s·sin(w·t) + (Δ0 − q_c)·
  e^{−t/τ_c} (τ_c = L_c/r_T, (q_c, q_s) its sinusoidal steady state); the outgoing
  branch's current (j − Δ)/2 reaches zero at the end.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "KIND_COMMUTATION",
    "KIND_COMMUTATION_R",
    "KIND_CURRENT",
    "KIND_IGNITION",
    "KIND_RISE",
    "charge",
    "current_at",
    "current_coeffs",
    "first_root",
    "root_params",
]

KIND_CURRENT = 0
KIND_IGNITION = 1
KIND_COMMUTATION = 2
KIND_RISE = 3
KIND_COMMUTATION_R = 4

_MAX_STEPS = 200
_REL_TOL = 1e-13


@numba.njit(cache=True)
def current_coeffs(vc, vs, g0, g1, r, l, w):
    """Particular solution of L·j' + R·j = v_c·cos(w·t) + v_s·sin(w·t) + g0 + g1·t.

    Returns
    -------
    (p_c, p_s, A, B, τ)
        P(t) = p_c·cos(w·t) + p_s·sin(w·t) + A + B·t (A, A/s) and τ = L/R (s).
    """
    lw = l * w
    det = r * r + lw * lw
    pc = (r * vc - lw * vs) / det
    ps = (r * vs + lw * vc) / det
    tau = l / r
    b = g1 / r
    a = (g0 - g1 * tau) / r
    return pc, ps, a, b, tau


@numba.njit(cache=True)
def current_at(t, j0, pc, ps, a, b, tau, w):
    """j(t) of the segment that starts at j0 (A)."""
    c = j0 - pc - a
    wt = w * t
    return pc * math.cos(wt) + ps * math.sin(wt) + a + b * t + c * math.exp(-t / tau)


@numba.njit(cache=True)
def charge(t, j0, pc, ps, a, b, tau, w):
    """∫₀ᵗ j dt of the segment that starts at j0 (A·s)."""
    c = j0 - pc - a
    wt = w * t
    h = math.sin(0.5 * wt)
    return ((pc * math.sin(wt) + ps * 2.0 * h * h) / w + a * t + 0.5 * b * t * t
            + c * tau * -math.expm1(-t / tau))


@numba.njit(cache=True)
def _evaluate(kind, p, t):
    """(F, F', F'', M2, M3, scale) of function ``kind`` at t: M2 ≥ |F''| and M3 ≥ |F'''|
    on [t, ∞), and the size of F's terms (for the tolerance)."""
    w = p[6]
    wt = w * t
    cw, sw = math.cos(wt), math.sin(wt)
    if kind == KIND_IGNITION:
        vc, vs, g0, g1 = p[0], p[1], p[2], p[3]
        amp = math.sqrt(vc * vc + vs * vs)
        f = -(vc * cw + vs * sw + g0 + g1 * t)
        f1 = -(w * (vs * cw - vc * sw) + g1)
        f2 = w * w * (vc * cw + vs * sw)
        return f, f1, f2, w * w * amp, w * w * w * amp, amp + abs(g0) + abs(g1 * t)
    j0, pc, ps, a, b, tau = p[0], p[1], p[2], p[3], p[4], p[5]
    c = j0 - pc - a
    e = math.exp(-t / tau)
    amp = math.sqrt(pc * pc + ps * ps)
    j = pc * cw + ps * sw + a + b * t + c * e
    j1 = w * (ps * cw - pc * sw) + b - c / tau * e
    j2 = -w * w * (pc * cw + ps * sw) + c / (tau * tau) * e
    m2 = w * w * amp + abs(c) / (tau * tau) * e
    m3 = w * w * w * amp + abs(c) / (tau * tau * tau) * e
    scale = amp + abs(a) + abs(b * t) + abs(c) + abs(j0)
    if kind == KIND_CURRENT:
        return j, j1, j2, m2, m3, scale
    if kind == KIND_RISE:
        return -j, -j1, -j2, m2, m3, scale
    if kind == KIND_COMMUTATION_R:
        # F = (j − Δ)/2, Δ = q_c·cos + q_s·sin + (Δ0 − q_c)·e^{−t/τ_c}
        qc, qs, tc, d0 = p[7], p[8], p[9], p[10]
        cd = d0 - qc
        ec = math.exp(-t / tc)
        qamp = math.sqrt(qc * qc + qs * qs)
        dd = qc * cw + qs * sw + cd * ec
        dd1 = w * (qs * cw - qc * sw) - cd / tc * ec
        dd2 = -w * w * (qc * cw + qs * sw) + cd / (tc * tc) * ec
        return (0.5 * (j - dd), 0.5 * (j1 - dd1), 0.5 * (j2 - dd2),
                0.5 * (m2 + w * w * qamp + abs(cd) / (tc * tc) * ec),
                0.5 * (m3 + w * w * w * qamp + abs(cd) / (tc * tc * tc) * ec),
                scale + qamp + abs(cd))
    # commutation: F = (j + J0)/2 − (D0 + D)/(2·L_c), D = ∫ (d_c·cos + d_s·sin) over the
    # segment; J0 is the current and D0 the integral when the overlap began
    dc, ds, lc = p[7], p[8], p[9]
    h = math.sin(0.5 * wt)
    d = (dc * sw + ds * 2.0 * h * h) / w
    d1 = dc * cw + ds * sw
    d2 = w * (ds * cw - dc * sw)
    damp = math.sqrt(dc * dc + ds * ds)
    k = 0.5 / lc
    f = 0.5 * (j + p[10]) - k * (p[11] + d)
    return (f, 0.5 * j1 - k * d1, 0.5 * j2 - k * d2, 0.5 * m2 + k * w * damp,
            0.5 * m3 + k * w * w * damp, scale + k * damp / w)


@numba.njit(cache=True)
def first_root(kind, p, h):
    """First t in [0, h] where F ≤ 0 (F of ``kind`` with parameters ``p``), or −1.0.

    ``p`` holds (j0, p_c, p_s, A, B, τ, w) for the current and the rise, further (d_c, d_s,
    L_c, J0, D0) for the commutation or (q_c, q_s, τ_c, Δ0) for the commutation with slope
    resistance, and (v_c, v_s, g0, g1, –, –, w) for the ignition. F(0) ≥ 0 is assumed; an
    F that starts at zero counts only if it does not rise from there.
    """
    f, f1, f2, m2, m3, scale = _evaluate(kind, p, 0.0)
    tol = _REL_TOL * scale
    t = 0.0
    if f < -tol:
        return 0.0
    if f <= tol:  # on a zero: a root unless F leaves it upward
        flat = tol / max(h, 1e-300)          # a slope that moves F by tol over the segment
        if f1 > flat and m2 > 0.0:
            t = f1 / m2                      # F ≥ F'·s − M2·s²/2 > 0 up to here
        elif f1 >= -flat and f2 > 0.0 and m3 > 0.0:
            t = 1.5 * f2 / m3                # F ≥ F'·s + F''·s²/2 − M3·s³/6 > 0
        else:
            return 0.0
        if t >= h:
            return -1.0
    for _ in range(_MAX_STEPS):
        f, f1, f2, m2, m3, scale = _evaluate(kind, p, t)
        if f <= tol:
            return t
        disc = math.sqrt(f1 * f1 + 2.0 * m2 * f)
        if disc - f1 <= 0.0:
            return -1.0  # no curvature and rising: F stays positive
        t += 2.0 * f / (disc - f1)  # the zero of F + F'·s − M2·s²/2 (stable form)
        if t >= h:
            return -1.0
    return t


def root_params(*values: float) -> np.ndarray:
    """Pack parameters for :func:`first_root` (a 12-element float64 array, zero-padded)."""
    p = np.zeros(12)
    p[:len(values)] = values
    return p
