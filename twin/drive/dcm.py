"""Discontinuous conduction of a p-pulse converter feeding R-L-E: the boundary in closed
form and the steady-state characteristic the drive's firing unit inverts.

Normalised units (all per converter, from :func:`twin.drive.bridge`'s segment solution):
x = ω_mains·t, a = ω_mains·L/R, e = E/Û and i = I·R/Û, with Û the peak of the voltage a
conducting pair applies (√2·U_LL for the 6-pulse bridge, √2·U_LL/√3 for the 3-pulse
midpoint circuit). Firing at angle α (from the natural commutation point) starts the pair
whose voltage is cos(x + x_on), x_on = α − π/p, for one pulse period X = 2π/p.

Boundary between the modes (closed form)
    At the boundary the steady current just touches zero at each firing: j(0) = j(X) = 0
    with j(x) = P(x) − P(0)·e^{−x/a} and P(x) = S·cos(x + x_on − ψ) − e, S = 1/√(1 + a²),
    ψ = arctan a. Hence, with κ = e^{−X/a},

        e_b(α) = S·[cos(X + x_on − ψ) − κ·cos(x_on − ψ)] / (1 − κ)
        i_b(α) = (p/π)·sin(π/p)·cos α − e_b(α)                (mean current, normalised)

    For R → 0 (a → ∞) this is the textbook I_b = Û/(ω·L)·(1 − (π/p)·cot(π/p))·sin α
    (0.0931·Û/(ω·L)·sin α for p = 6): about 4.2 A·sin α for the Tomsk drive.

Discontinuous characteristic (numerical, tabulated)
    Below the boundary each pulse starts from zero: at the firing if the pair is forward
    biased (cos x_on > e), else where cos(x + x_on) rises through e (long gate pulses), and
    ends at the current's first zero x_z. The mean current is i = ∫j dx / X. A drive's
    firing unit inverts i(α, e) for α (:func:`dcm_angle`), which restores the gain the
    current loop was designed for (``converter.dcm_compensation``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from twin.drive.bridge import KIND_CURRENT, charge, current_coeffs, first_root

__all__ = [
    "N_ALPHA",
    "N_EMF",
    "boundary_current",
    "boundary_emf",
    "build_table",
    "dcm_angle",
    "dcm_current",
]

N_ALPHA = 181
"""Firing-angle grid of the table: 0 … π in 1° steps."""
N_EMF = 101
"""EMF grid of the table: e = −1 … 1 in steps of 0.02."""

_CCM = 1e30  # table entry of an (α, e) where the current does not stop: continuous


@numba.njit(cache=True)
def boundary_emf(alpha, p, a):
    """e_b(α): normalised EMF at which the steady current just becomes continuous."""
    x = 2.0 * math.pi / p
    x_on = alpha - math.pi / p
    s = 1.0 / math.sqrt(1.0 + a * a)
    psi = math.atan(a)
    kappa = math.exp(-x / a)
    return s * (math.cos(x + x_on - psi) - kappa * math.cos(x_on - psi)) / (1.0 - kappa)


@numba.njit(cache=True)
def boundary_current(alpha, p, a):
    """i_b(α): normalised mean current at the boundary between the modes (I·R/Û)."""
    return p / math.pi * math.sin(math.pi / p) * math.cos(alpha) - boundary_emf(alpha, p, a)


@numba.njit(cache=True)
def dcm_current(alpha, e, p, a):
    """Normalised steady mean current i = I·R/Û for firing angle α and EMF e, or 1e30 where
    the current does not stop before the next firing (continuous conduction)."""
    x_pulse = 2.0 * math.pi / p
    x_on = alpha - math.pi / p
    x_start = 0.0
    if math.cos(x_on) <= e:  # reverse biased at the firing: wait for cos(x + x_on) = e
        if e >= 1.0:
            return 0.0
        x_rise = -math.acos(e) - x_on      # where cos rises through e
        if x_rise < 0.0:
            x_rise += 2.0 * math.pi
        if x_rise >= x_pulse:
            return 0.0
        x_start = x_rise
    ph = x_on + x_start
    pc, ps, aa, bb, tau = current_coeffs(math.cos(ph), -math.sin(ph), -e, 0.0, 1.0, a, 1.0)
    p_root = np.zeros(12)
    p_root[0], p_root[1], p_root[2], p_root[3], p_root[4], p_root[5], p_root[6] = (
        0.0, pc, ps, aa, bb, tau, 1.0)
    span = x_pulse - x_start
    x_z = first_root(KIND_CURRENT, p_root, span)
    if x_z < 0.0:
        return _CCM
    return charge(x_z, 0.0, pc, ps, aa, bb, tau, 1.0) / x_pulse


@numba.njit(cache=True)
def build_table(p, a):
    """The discontinuous characteristic on the grid: table[k, m] = i(α_m, e_k) (1e30 where
    continuous), α_m = m·π/(N_ALPHA − 1), e_k = −1 + 2·k/(N_EMF − 1)."""
    table = np.empty((N_EMF, N_ALPHA))
    for k in range(N_EMF):
        e = -1.0 + 2.0 * k / (N_EMF - 1)
        for m in range(N_ALPHA):
            table[k, m] = dcm_current(m * math.pi / (N_ALPHA - 1), e, p, a)
    return table


@numba.njit(cache=True)
def _row_angle(table, k, i_target, m_lo, m_hi):
    """α on row k where the (decreasing) characteristic equals i_target, by bisection over
    the grid and linear interpolation; clamped to the grid indices [m_lo, m_hi]."""
    row = table[k]
    if row[m_lo] <= i_target:
        return m_lo * math.pi / (N_ALPHA - 1)
    if row[m_hi] >= i_target:
        return m_hi * math.pi / (N_ALPHA - 1)
    lo, hi = m_lo, m_hi  # row[lo] > i_target >= row[hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if row[mid] > i_target:
            lo = mid
        else:
            hi = mid
    v_lo = row[lo]
    frac = 0.0 if v_lo >= _CCM else (v_lo - i_target) / (v_lo - row[hi])
    return (lo + frac) * math.pi / (N_ALPHA - 1)


@numba.njit(cache=True)
def dcm_angle(table, i_target, e, alpha_min, alpha_max):
    """Firing angle (rad) at which the steady discontinuous current is ``i_target``
    (normalised) against EMF ``e`` (normalised), within [alpha_min, alpha_max]."""
    step = math.pi / (N_ALPHA - 1)
    m_lo = min(max(math.ceil(alpha_min / step - 1e-9), 0), N_ALPHA - 1)
    m_hi = min(max(math.floor(alpha_max / step + 1e-9), 0), N_ALPHA - 1)
    pos = (min(max(e, -1.0), 1.0) + 1.0) * 0.5 * (N_EMF - 1)
    k = min(int(pos), N_EMF - 2)
    w = pos - k
    alpha = ((1.0 - w) * _row_angle(table, k, i_target, m_lo, m_hi)
             + w * _row_angle(table, k + 1, i_target, m_lo, m_hi))
    return min(max(alpha, alpha_min), alpha_max)
