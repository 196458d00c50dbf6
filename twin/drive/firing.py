"""The firing unit and the current regulator of the pulse-level drive, at each regulator
sample (numba, scalar; called by :mod:`twin.drive.pulse`).

A digital drive synchronised to the mains
    The regulators sample once per pulse, at the instant the previous firing angle would
    fire the next pair: t_s = J·T_p + α_{J−1}/ω. They compute α_J and fire pair J at
    max(t_s, J·T_p + α_J/ω): at once when the demand rose (as vertical firing control does
    when the control voltage crosses its cosine reference early), later when it fell. The
    converter's dead time is then T_p/2 on average, as in the design.
    The current regulator measures the *pulse-mean* current (the charge since the last
    sample over the time), as digital thyristor drives do; that averaging adds T_p/2 to the
    loop's small time constant (:mod:`twin.drive.design`). Its output is a mean-voltage
    demand V*. The firing unit turns V* into α by the arccos law, or, with discontinuous
    conduction compensation (``converter.dcm_compensation``), by the inverse of the
    discontinuous characteristic where V* asks for a current below the boundary
    (:mod:`twin.drive.dcm`), and the regulator then runs as an integral controller per
    pulse on the static discontinuous plant (see ``models/README.md``, "Discontinuous
    conduction").

An analog drive (``regulators.implementation = "analog"``, :mod:`twin.drive.analog`) has no
sampled regulator: at the sample the firing unit reads the control voltage of its continuous
current regulator, E_est + K_pi·(i* − i_f) + S_i, from the filtered current i_f, and fires
by the arccos law (or, with ``converter.dcm_compensation``, by the inverse of the
discontinuous characteristic: an adaptive analog firing unit's function generator).
"""

from __future__ import annotations

import math

import numba

from twin.drive.dcm import boundary_current, dcm_angle
from twin.drive.layout import (
    P_AMAX,
    P_AMIN,
    P_DCMC,
    P_DCMG,
    P_EMFC,
    P_ITH,
    P_K,
    P_KC,
    P_KPC,
    P_L,
    P_LC,
    P_NSER,
    P_PAUSE,
    P_PN,
    P_R,
    P_TIC,
    P_UHAT,
    P_UMAX,
    P_VHI,
    P_VLO,
    P_WM,
    S_BRIDGE,
    S_CINT,
    S_I,
    S_IF,
    S_IREF,
    S_MODE,
    S_PAUSE_END,
)
from twin.drive.loops import pi_step, reset_regulators

__all__ = ["analog_current_regulator", "block", "bridge_logic", "current_regulator",
           "firing_angle"]

_EPS = 1e-12


@numba.njit(cache=True)
def firing_angle(pa, table, v_star, e_b):
    """Firing unit: the angle (rad) that gives the mean-voltage demand ``v_star`` (V,
    conducting sense) against the EMF estimate ``e_b`` (V, conducting sense)."""
    a_min, a_max = pa[P_AMIN], pa[P_AMAX]
    c = min(max(v_star / pa[P_UMAX], -1.0), 1.0)
    alpha = min(max(math.acos(c), a_min), a_max)
    if pa[P_DCMC] == 0.0:
        return alpha
    r, u_hat = pa[P_R], pa[P_UHAT]
    if v_star >= pa[P_VHI]:
        return a_min  # the demand saturates the converter: full voltage
    i_star = (v_star - e_b) / r
    if i_star <= 0.0:
        return a_max  # no current wanted: the angle at which none can flow
    a = pa[P_WM] * (pa[P_L] + pa[P_NSER] * pa[P_LC]) / r
    if i_star * r / u_hat >= boundary_current(alpha, pa[P_PN], a):
        return alpha  # continuous conduction: the arccos law is exact on average
    return dcm_angle(table, i_star * r / u_hat, e_b / u_hat, a_min, a_max)


@numba.njit(cache=True)
def bridge_logic(pa, st, t, e_est):
    """The logic switching unit of the non-circulating pair: selects a bridge for the
    current reference, reverses only at zero current after the pause; returns the bridge."""
    i_ref = st[S_IREF]
    b = st[S_BRIDGE]
    if b == 0.0:
        if t >= st[S_PAUSE_END] - _EPS and abs(i_ref) > pa[P_ITH]:
            b = 1.0 if i_ref > 0.0 else -1.0
            # start at the EMF balance (no current surge); a start is discontinuous
            st[S_CINT] = 0.0 if pa[P_EMFC] != 0.0 else b * e_est
            st[S_MODE] = 1.0 if pa[P_DCMC] != 0.0 else 0.0
    elif b * i_ref < -pa[P_ITH] and st[S_I] == 0.0:
        b = 0.0  # zero current confirmed: remove pulses, let the thyristors recover
        st[S_PAUSE_END] = t + pa[P_PAUSE]
        st[S_CINT] = 0.0
    st[S_BRIDGE] = b
    return b


@numba.njit(cache=True)
def _select(pa, st, t, tacho):
    """Bridge logic at a sample from the tacho sample (V): (the bridge, 0 if blocked; the
    EMF compensation in its conducting sense (V))."""
    e_est = pa[P_K] / pa[P_KC] * tacho
    b = bridge_logic(pa, st, t, e_est)
    return b, (b * e_est if pa[P_EMFC] != 0.0 else 0.0)


@numba.njit(cache=True)
def analog_current_regulator(pa, st, t, tacho):
    """Bridge logic and the analog current regulator's output now: the control voltage
    (V, conducting sense) from the filtered current, or NaN with the bridge blocked."""
    b, ff = _select(pa, st, t, tacho)
    if b == 0.0:
        return math.nan
    v = ff + pa[P_KPC] * b * (st[S_IREF] - st[S_IF]) + st[S_CINT]
    return min(max(v, pa[P_VLO]), pa[P_VHI])


@numba.njit(cache=True)
def current_regulator(pa, st, t, i_meas, dcm, interval, tacho):
    """Bridge logic and current regulator; returns the mean-voltage demand (V, conducting
    sense of the selected bridge) or NaN with the bridge blocked."""
    i_ref = st[S_IREF]
    b, ff = _select(pa, st, t, tacho)
    if b == 0.0:
        return math.nan
    lo, hi = pa[P_VLO], pa[P_VHI]
    err = b * (i_ref - i_meas)
    r = pa[P_R]
    mode = 1.0 if (dcm and pa[P_DCMC] != 0.0) else 0.0
    t_ratio = interval / pa[P_TIC]
    kp = pa[P_KPC]
    if mode != st[S_MODE]:  # bumpless transfer: the demand stays where it was
        p_ccm = kp * (1.0 + 0.5 * t_ratio) * err
        p_dcm = r * b * i_ref
        st[S_CINT] += (p_ccm - p_dcm) if mode == 1.0 else (p_dcm - p_ccm)
        st[S_MODE] = mode
    if mode == 1.0:
        # discontinuous: each pulse starts from zero, the linearised plant is 1/R without
        # lag; the model's demand R·i_ref plus an integral of the residual (gain g/pulse)
        v = ff + r * b * i_ref + st[S_CINT]
        integ = st[S_CINT] + pa[P_DCMG] * r * err
        if v >= hi:
            v = hi
            integ = min(integ, st[S_CINT])
        elif v <= lo:
            v = lo
            integ = max(integ, st[S_CINT])
        st[S_CINT] = min(max(integ, lo - hi), hi - lo)
        return v
    freeze = b * i_meas <= 0.0 and err < 0.0  # no current to lower: hold, do not wind
    v, st[S_CINT] = pi_step(err, st[S_CINT], kp, t_ratio, lo - ff, hi - ff, freeze)
    return v + ff


@numba.njit(cache=True)
def block(pa, st):
    """Disabled or tripped: regulators reset, a flowing current driven to zero at the
    inverter end stop; returns the angle (NaN: pulses removed)."""
    reset_regulators(st)
    if st[S_I] == 0.0:
        st[S_BRIDGE] = 0.0
        return math.nan
    st[S_BRIDGE] = 1.0 if st[S_I] > 0.0 else -1.0
    return pa[P_AMAX]
