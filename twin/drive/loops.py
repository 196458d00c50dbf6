"""Pieces both converter models share (numba, scalar): the sampled PI regulator, the speed
regulator with the overload trip, the tachogenerator and the two first-order filters over a
piece of an interval.
"""

from __future__ import annotations

import math

import numba

from twin.drive.armature import first_order
from twin.drive.layout import (
    NRIPPLE,
    P_ILIM,
    P_KC,
    P_KPS,
    P_OVERLOAD,
    P_RIPPLE,
    P_T1,
    P_TF,
    P_TIS,
    S_CINT,
    S_FAULT,
    S_IREF,
    S_REF,
    S_SAT,
    S_SINT,
    S_TACHO,
)

__all__ = ["advance_filters", "current_reference", "pi_step", "reset_regulators",
           "ripple_factor", "speed_regulator"]


@numba.njit(cache=True)
def pi_step(error, integ, kp, t_ratio, lo, hi, freeze):
    """Sampled PI (Tustin) with clamping anti-windup; returns (output, new integrator).

    u_k = K_p·(1 + T/(2·T_i))·e_k + S_k, S_{k+1} = S_k + K_p·(T/T_i)·e_k, u clamped to
    [lo, hi]; S does not integrate further into a limit, nor when ``freeze`` is set.
    """
    out = kp * (1.0 + 0.5 * t_ratio) * error + integ
    step = kp * t_ratio * error
    if out >= hi:
        out = hi
        if step > 0.0:
            step = 0.0
    elif out <= lo:
        out = lo
        if step < 0.0:
            step = 0.0
    if not freeze:
        integ = min(max(integ + step, lo), hi)
    return out, integ


@numba.njit(cache=True)
def speed_regulator(pa, st, tacho, interval):
    """Speed PI → current reference (A) with the current limit; counts the time at the
    limit and trips the overload fault. Returns False if the drive just tripped."""
    i_lim = pa[P_ILIM]
    i_ref, st[S_SINT] = pi_step(st[S_REF] - tacho, st[S_SINT], pa[P_KPS], interval / pa[P_TIS],
                                -i_lim, i_lim, False)
    return current_reference(pa, st, i_ref, interval)


@numba.njit(cache=True)
def current_reference(pa, st, i_ref, interval):
    """Set the current reference ``i_ref`` (A, already limited) and count the time it has
    been at the current limit; trips the overload fault and returns False once that has
    lasted ``overload_time``."""
    st[S_IREF] = i_ref
    st[S_SAT] = st[S_SAT] + interval if abs(i_ref) >= pa[P_ILIM] else 0.0
    if st[S_SAT] >= pa[P_OVERLOAD]:
        st[S_FAULT] = 1.0
        return False
    return True


@numba.njit(cache=True)
def reset_regulators(st):
    """Disabled or tripped: both regulators' integrators, the current reference and the
    time at the limit back to zero."""
    st[S_SINT] = 0.0
    st[S_CINT] = 0.0
    st[S_IREF] = 0.0
    st[S_SAT] = 0.0


@numba.njit(cache=True)
def ripple_factor(pa, theta):
    """1 + Σ A_h·sin(h·θ): the tachogenerator's EMF per unit of K_C·ω at rotor angle θ."""
    f = 1.0
    for k in range(NRIPPLE):
        amp = pa[P_RIPPLE + 2 * k + 1]
        if amp != 0.0:
            f += amp * math.sin(pa[P_RIPPLE + 2 * k] * theta)
    return f


@numba.njit(cache=True)
def advance_filters(pa, st, active, u_in, w_t, slope, theta_mid, h):
    """Reference filter T1 and tacho filter T_f over a piece of length h that starts at rotor
    speed w_t with slope dω/dt (ripple evaluated at the piece's middle angle)."""
    st[S_REF] = first_order(st[S_REF], u_in, 0.0, h, pa[P_T1]) if active else 0.0
    f = ripple_factor(pa, theta_mid)
    st[S_TACHO] = first_order(st[S_TACHO], pa[P_KC] * w_t * f, pa[P_KC] * slope * f, h,
                              pa[P_TF])
