"""The pulse-level thyristor converter and its regulators over one drive interval (numba).

Circuit (``converter.model = "pulse"``)
    A non-circulating pair of line-commutated converters: 6-pulse bridges (``pulse_number =
    6``) or 3-pulse midpoint circuits (3). Natural commutation point J is at
    t = J·T_p + t_0 (T_p = 1/(p·f); t_0 from ``converter.mains_phase``, the mains' phase at
    the twin's time 0), and the pair fired for J applies, in the conducting sense of its
    converter, u_J(t) = Û·cos(ω·(t − J·T_p − t_0) − π/p), the
    instantaneous line-to-line (bridge) or phase (midpoint) voltage. The converter
    conducts in one sense only: the current stops where it reaches zero and starts again
    where a pair whose gate pulse is on is forward biased (long gate pulses, on until the
    next firing). A firing while current flows commutates it to the new pair, at once, or,
    with a line inductance L_c > 0, through an overlap during which the output is the mean
    of the two voltages and the incoming thyristor takes the current at the rate
    (u_in − u_out)/(2·L_c). Every event (firing, extinction, ignition, end of overlap) is
    located exactly within the interval (:mod:`twin.drive.bridge`).

Firing control and regulators (a digital drive synchronised to the mains)
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
"""

from __future__ import annotations

import math

import numba

from twin.drive.bridge import (
    KIND_COMMUTATION,
    KIND_CURRENT,
    KIND_IGNITION,
    charge,
    current_at,
    current_coeffs,
    first_root,
)
from twin.drive.dcm import boundary_current, dcm_angle
from twin.drive.layout import (
    P_ALPHA_FIX,
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
    P_T0,
    P_TIC,
    P_TP,
    P_UHAT,
    P_UMAX,
    P_VHI,
    P_VLO,
    P_WM,
    S_ALAST,
    S_ALPHA,
    S_BRIDGE,
    S_CINT,
    S_CONDUCT,
    S_FIRE_AT,
    S_FIRE_J,
    S_I,
    S_IMEAS,
    S_IREF,
    S_J,
    S_MODE,
    S_NEXT,
    S_NLOG,
    S_OVL,
    S_OVL_D,
    S_OVL_J0,
    S_PAIR,
    S_PAUSE_END,
    S_PULSE,
    S_Q,
    S_SAT,
    S_SINT,
    S_TACHO,
    S_TLAST,
    S_V,
    S_ZERO,
)
from twin.drive.loops import advance_filters, pi_step, speed_regulator

__all__ = ["advance_pulse"]

_EPS = 1e-12
_MAX_ZERO_EVENTS = 64  # zero-length events in one interval before a forced 1 ps step


@numba.njit(cache=True)
def _phasor(pa, t, pair):
    """(v_c, v_s): the voltage of ``pair`` from time t on, as v_c·cos(ω·s) + v_s·sin(ω·s)."""
    ph = pa[P_WM] * (t - pair * pa[P_TP] - pa[P_T0]) - math.pi / pa[P_PN]
    u = pa[P_UHAT]
    return u * math.cos(ph), -u * math.sin(ph)


@numba.njit(cache=True)
def _log(st, log_row, t, pair, bridge, alpha):
    n = int(st[S_NLOG])
    if n < log_row.shape[0]:
        log_row[n, 0] = t
        log_row[n, 1] = pair
        log_row[n, 2] = bridge
        log_row[n, 3] = alpha
        st[S_NLOG] = n + 1


@numba.njit(cache=True)
def _fire(pa, st, t, log_row):
    """Fire the pending pair: gate pulses move to it; a flowing current commutates."""
    pair = st[S_FIRE_J]
    st[S_FIRE_AT] = math.inf
    b = st[S_BRIDGE]
    if b == 0.0:
        return
    j = b * st[S_I]
    if j > 0.0 and st[S_PULSE] != 0.0 and pa[P_LC] > 0.0 and pair == st[S_PAIR] + 1.0:
        st[S_OVL] = 1.0          # overlap: the outgoing pair keeps conducting for a while
        st[S_OVL_J0] = j
        st[S_OVL_D] = 0.0
    else:
        st[S_OVL] = 0.0          # instantaneous commutation (or a start from zero)
    st[S_PAIR] = pair
    st[S_PULSE] = 1.0
    _log(st, log_row, t, pair, b, st[S_ALPHA])


@numba.njit(cache=True)
def _firing_angle(pa, table, v_star, e_b):
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
def _current_regulator(pa, st, t, i_meas, dcm, interval, tacho):
    """Bridge logic and current regulator; returns the mean-voltage demand (V, conducting
    sense of the selected bridge) or NaN with the bridge blocked."""
    i_ref = st[S_IREF]
    b = st[S_BRIDGE]
    e_est = pa[P_K] / pa[P_KC] * tacho
    ff_on = pa[P_EMFC] != 0.0
    if b == 0.0:
        if t >= st[S_PAUSE_END] - _EPS and abs(i_ref) > pa[P_ITH]:
            b = 1.0 if i_ref > 0.0 else -1.0
            # start at the EMF balance (no current surge); a start is discontinuous
            st[S_CINT] = 0.0 if ff_on else b * e_est
            st[S_MODE] = 1.0 if pa[P_DCMC] != 0.0 else 0.0
    elif b * i_ref < -pa[P_ITH] and st[S_I] == 0.0:
        b = 0.0  # zero current confirmed: remove pulses, let the thyristors recover
        st[S_PAUSE_END] = t + pa[P_PAUSE]
        st[S_CINT] = 0.0
    st[S_BRIDGE] = b
    if b == 0.0:
        return math.nan
    lo, hi = pa[P_VLO], pa[P_VHI]
    ff = b * e_est if ff_on else 0.0
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
def _sample(pa, st, table, t, active, tacho, log_row):
    """Regulator sample for natural commutation point J: speed and current regulators (or
    the open-loop angle, or the inverter end stop when disabled), then schedule the firing
    of pair J and the next sample."""
    interval = t - st[S_TLAST]
    i_meas = st[S_Q] / interval if interval > _EPS else st[S_I]
    st[S_Q] = 0.0
    st[S_TLAST] = t
    st[S_IMEAS] = i_meas
    dcm = st[S_ZERO] != 0.0 or st[S_I] == 0.0
    st[S_ZERO] = 1.0 if st[S_I] == 0.0 else 0.0
    j_nat = st[S_J]
    st[S_J] = j_nat + 1.0
    alpha = math.nan
    if math.isfinite(pa[P_ALPHA_FIX]):  # open-loop converter (tests, identification)
        st[S_BRIDGE] = 1.0 if active else (0.0 if st[S_I] == 0.0 else st[S_BRIDGE])
        if st[S_BRIDGE] != 0.0:
            alpha = pa[P_ALPHA_FIX] if active else pa[P_AMAX]
    elif active and speed_regulator(pa, st, tacho, interval):
        v = _current_regulator(pa, st, t, i_meas, dcm, interval, tacho)
        if v == v:
            e_b = st[S_BRIDGE] * pa[P_K] / pa[P_KC] * tacho
            alpha = _firing_angle(pa, table, v, e_b)
    else:  # disabled or tripped: regulators reset, a flowing current driven to zero
        st[S_SINT] = 0.0
        st[S_CINT] = 0.0
        st[S_IREF] = 0.0
        st[S_SAT] = 0.0
        if st[S_I] == 0.0:
            st[S_BRIDGE] = 0.0
        else:
            st[S_BRIDGE] = 1.0 if st[S_I] > 0.0 else -1.0
            alpha = pa[P_AMAX]
    w = pa[P_WM]
    t_nat = j_nat * pa[P_TP] + pa[P_T0]
    if alpha == alpha:
        st[S_ALPHA] = alpha
        st[S_ALAST] = alpha
        st[S_V] = st[S_BRIDGE] * pa[P_UMAX] * math.cos(alpha)
        st[S_FIRE_AT] = max(t, t_nat + alpha / w)
        st[S_FIRE_J] = j_nat
    else:
        if st[S_PULSE] != 0.0:
            _log(st, log_row, t, st[S_PAIR], 0.0, math.nan)  # gate pulses removed
        st[S_ALPHA] = math.nan
        st[S_V] = 0.0
        st[S_FIRE_AT] = math.inf
        st[S_PULSE] = 0.0
        st[S_OVL] = 0.0
    st[S_NEXT] = t_nat + pa[P_TP] + st[S_ALAST] / w


@numba.njit(cache=True)
def _reverse_biased_throughout(vc, vs, g0, g1, w, h):
    """True if the driving voltage g(s) = v_c·cos(w·s) + v_s·sin(w·s) + g0 + g1·s stays ≤ 0
    on [0, h] by a cheap bound (the sinusoid's largest value over the phase span, the ramp's
    larger end); False means "search": most pieces after an extinction end here."""
    amp = math.sqrt(vc * vc + vs * vs)
    if amp == 0.0:
        return g0 + max(0.0, g1 * h) <= 0.0
    phi0 = math.atan2(-vs, vc)            # v_c·cos + v_s·sin = amp·cos(w·s + phi0)
    wh = w * h
    if -wh <= phi0 <= 0.0:
        top = amp                         # the crest lies inside the piece
    else:
        top = max(vc, vc * math.cos(wh) + vs * math.sin(wh))
    return top + g0 + max(0.0, g1 * h) <= 0.0


@numba.njit(cache=True)
def _conduct(pa, st, p, t, h, e0, e1, bins, s0, bin_w):
    """Armature over [t, t + h] with the gate pulses on: returns (time advanced, charge in
    the motor's sense, conducting time). Stops early at an ignition, an extinction or the
    end of an overlap (the state then describes that instant). The charge is also added to
    ``bins`` (the interval's sub-steps of width ``bin_w``; the piece starts ``s0`` into the
    interval), split exactly at their boundaries."""
    b = st[S_BRIDGE]
    j0 = b * st[S_I]
    pair = st[S_PAIR]
    w = pa[P_WM]
    g0, g1 = -b * e0, -b * e1
    vc, vs = _phasor(pa, t, pair)
    overlap = st[S_OVL] != 0.0
    if overlap:
        oc, os_ = _phasor(pa, t, pair - 1.0)
        dc, ds = vc - oc, vs - os_
        vc, vs = 0.5 * (vc + oc), 0.5 * (vs + os_)
    if j0 <= 0.0:  # not conducting: wait until the pair is forward biased
        if _reverse_biased_throughout(vc, vs, g0, g1, w, h):
            return h, 0.0, 0.0
        p[0], p[1], p[2], p[3], p[6] = vc, vs, g0, g1, w
        t_on = first_root(KIND_IGNITION, p, h)
        if t_on < 0.0:
            return h, 0.0, 0.0
        if t_on > 0.0:
            return t_on, 0.0, 0.0
        j0 = 0.0
    series = pa[P_NSER] - 0.5 if overlap else pa[P_NSER]
    l_eff = pa[P_L] + series * pa[P_LC]
    pc, ps, a, bb, tau = current_coeffs(vc, vs, g0, g1, pa[P_R], l_eff, w)
    p[0], p[1], p[2], p[3], p[4], p[5], p[6] = j0, pc, ps, a, bb, tau, w
    t_end = h
    event = 0
    t_z = first_root(KIND_CURRENT, p, h)
    if t_z >= 0.0:
        t_end, event = t_z, 1
    if overlap:
        p[7], p[8], p[9], p[10], p[11] = dc, ds, pa[P_LC], st[S_OVL_J0], st[S_OVL_D]
        t_c = first_root(KIND_COMMUTATION, p, t_end)
        if t_c >= 0.0 and (event == 0 or t_c < t_end):
            t_end, event = t_c, 2
        wt = w * t_end
        hh = math.sin(0.5 * wt)
        st[S_OVL_D] += (dc * math.sin(wt) + ds * 2.0 * hh * hh) / w
    q = charge(t_end, j0, pc, ps, a, bb, tau, w)
    # the charge of each sub-step the piece spans, from the closed form at their boundaries
    m = bins.shape[0]
    k = min(int(s0 / bin_w), m - 1)
    q_done = 0.0
    while k < m - 1 and (k + 1) * bin_w < s0 + t_end:
        q_k = charge((k + 1) * bin_w - s0, j0, pc, ps, a, bb, tau, w)
        bins[k] += b * max(q_k - q_done, 0.0)
        q_done = q_k
        k += 1
    bins[k] += b * max(q - q_done, 0.0)
    if event == 1:
        st[S_I] = 0.0
        st[S_ZERO] = 1.0
        st[S_OVL] = 0.0
    else:
        st[S_I] = b * max(current_at(t_end, j0, pc, ps, a, bb, tau, w), 0.0)
        if event == 2:
            st[S_OVL] = 0.0
    return t_end, b * max(q, 0.0), t_end


@numba.njit(cache=True)
def advance_pulse(pa, st, table, t0, t_end, w0, slope, theta0, active, u_in, sigma,
                  noise_row, log_row, p, bins):
    """Advance one axis with the pulse-level converter over [t0, t_end]; returns the charge
    ∫i dt (A·s) and adds each sub-step's share to ``bins`` (m equal sub-steps of the
    interval). ``p`` is a 12-element scratch array for the root finder."""
    t = t0
    t_f = t0  # the filters are advanced to here, lazily: only a sample and the end need them
    bin_w = (t_end - t0) / bins.shape[0]
    q_total = 0.0
    k_noise = 0
    zero_events = 0
    conducting = 0.0
    while True:
        if st[S_FIRE_AT] <= t + _EPS:
            _fire(pa, st, t, log_row)
            continue
        if st[S_NEXT] <= t + _EPS:
            if t > t_f:
                _filters_to(pa, st, active, u_in, t0, t_f, t, w0, slope, theta0)
                t_f = t
            tacho = st[S_TACHO] + sigma * noise_row[k_noise]
            if k_noise < noise_row.shape[0] - 2:  # the last sample is the ADC's
                k_noise += 1
            _sample(pa, st, table, t, active, tacho, log_row)
            continue
        seg_end = min(st[S_NEXT], st[S_FIRE_AT], t_end)
        if seg_end > t_end - _EPS:
            seg_end = t_end
        h = seg_end - t
        s = t - t0
        w_t = w0 + slope * s
        e0 = pa[P_K] * w_t
        e1 = pa[P_K] * slope
        if st[S_BRIDGE] != 0.0 and st[S_PULSE] != 0.0:
            done, q, on = _conduct(pa, st, p, t, h, e0, e1, bins, s, bin_w)
        else:
            done, q, on = h, 0.0, 0.0
        if done <= 0.0:
            zero_events += 1
            if zero_events > _MAX_ZERO_EVENTS:
                done = min(1e-12, h)
        q_total += q
        st[S_Q] += q
        conducting += on
        t += done
        if done >= h and seg_end == t_end:
            break
    if t_end > t_f:
        _filters_to(pa, st, active, u_in, t0, t_f, t_end, w0, slope, theta0)
    st[S_CONDUCT] = conducting / (t_end - t0)
    return q_total


@numba.njit(cache=True)
def _filters_to(pa, st, active, u_in, t0, t_a, t_b, w0, slope, theta0):
    """Reference and tacho filters from t_a to t_b in one exact step (their inputs are a
    constant and a ramp over the whole interval; the tacho ripple is taken at the span's
    middle angle)."""
    s = t_a - t0
    h = t_b - t_a
    mid = s + 0.5 * h
    advance_filters(pa, st, active, u_in, w0 + slope * s, slope,
                    theta0 + w0 * mid + 0.5 * slope * mid * mid, h)
