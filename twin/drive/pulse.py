"""The pulse-level thyristor converter and its regulators over one drive interval (numba).

Circuit (``converter.model = "pulse"``)
    A non-circulating pair of line-commutated converters: 6-pulse bridges (``pulse_number =
    6``) or 3-pulse midpoint circuits (3). Natural commutation point J is at
    t = J·T_p + t_0 (T_p = 1/(p·f); t_0 from ``converter.mains_phase``, the mains' phase at
    the twin's time 0), and the pair fired for J applies, in the conducting sense of its
    converter, u_J(t) = Û·cos(ω·(t − J·T_p − t_0) − π/p), the
    instantaneous line-to-line (bridge) or phase (midpoint) voltage. The converter
    conducts in one sense only: the current stops where it reaches zero and starts again
    where a pair whose gate pulse is on is forward biased (by default long gate pulses, on
    until the next firing). A firing while current flows commutates it to the new pair, at
    once, or, with a line inductance L_c > 0, through an overlap during which the output is
    the mean of the two voltages and the incoming thyristor takes the current at the rate
    (u_in − u_out − r_T·(i_in − i_out))/(2·L_c). Every event (firing, extinction, ignition,
    end of overlap, end of a gate pulse, latching) is located exactly within the interval
    (:mod:`twin.drive.bridge`).

Firing control and regulators
    Sampled once per pulse (:mod:`twin.drive.firing`): the regulators run at the instant
    the previous firing angle would fire the next pair, t_s = J·T_p + α_{J−1}/ω, and pair J
    fires at max(t_s, J·T_p + α_J/ω).

Low-current physics
    The armature circuit carries the constant drop U_v = U_b + n_d·V_T0 of the brushes and
    the n_d thyristors in series (2 bridge, 1 midpoint; against the current while it flows)
    and their slope resistances R_eff = R + n_d·r_T (R + (n_d − ½)·r_T during an overlap,
    the commutating group's two branches in parallel), a smoothing reactor adds to L, and
    the mains applies Û·(1 + δ) (``converter.mains_deviation``; the firing unit and the
    regulators work with the rated Û). Each firing gates its pair for
    ``converter.gate_pulse_width`` (0: until the next firing, a long pulse). A gated pair
    starts where it is forward biased (u − E − U_v > 0), and a gated thyristor conducts down
    to zero current. When the gate pulse ends, a current that has not reached the latching
    current I_L is cut (the thyristor does not stay on); a latched one flows until it falls
    to the holding current I_H. With long pulses neither decides anything: that is why
    firing units of DC drives give long pulses; a pulse-transformer unit's short pulse lets
    both act at light load.
"""

from __future__ import annotations

import math

import numba

from twin.drive import analog, firing
from twin.drive.bridge import (
    KIND_COMMUTATION,
    KIND_COMMUTATION_R,
    KIND_CURRENT,
    KIND_IGNITION,
    KIND_RISE,
    charge,
    current_at,
    current_coeffs,
    first_root,
)
from twin.drive.layout import (
    P_ALPHA_FIX,
    P_AMAX,
    P_ANALOG,
    P_IH,
    P_IL,
    P_K,
    P_KC,
    P_L,
    P_LC,
    P_NSER,
    P_PN,
    P_R,
    P_RT,
    P_T0,
    P_TFI,
    P_TG,
    P_TP,
    P_UDROP,
    P_UMAX,
    P_UREAL,
    P_WM,
    S_ALAST,
    S_ALPHA,
    S_BRIDGE,
    S_CONDUCT,
    S_FIRE_AT,
    S_FIRE_J,
    S_GATE_END,
    S_I,
    S_IF,
    S_IMEAS,
    S_J,
    S_LATCH,
    S_NEXT,
    S_NLOG,
    S_OVL,
    S_OVL_D,
    S_OVL_J0,
    S_PAIR,
    S_PULSE,
    S_Q,
    S_QA,
    S_TACHO,
    S_TLAST,
    S_V,
    S_ZERO,
)
from twin.drive.loops import advance_filters, speed_regulator

__all__ = ["advance_pulse"]

_EPS = 1e-12
_MAX_ZERO_EVENTS = 64  # zero-length events in one interval before a forced 1 ps step


@numba.njit(cache=True)
def _phasor(pa, t, pair):
    """(v_c, v_s): the voltage of ``pair`` from time t on, as v_c·cos(ω·s) + v_s·sin(ω·s)."""
    ph = pa[P_WM] * (t - pair * pa[P_TP] - pa[P_T0]) - math.pi / pa[P_PN]
    u = pa[P_UREAL]
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
    if j > 0.0 and pa[P_LC] > 0.0 and pair == st[S_PAIR] + 1.0:
        st[S_OVL] = 1.0          # overlap: the outgoing pair keeps conducting for a while
        st[S_OVL_J0] = j
        st[S_OVL_D] = 0.0 if pa[P_RT] == 0.0 else -j   # ∫(u_in − u_out) dt, or Δ
    else:
        st[S_OVL] = 0.0          # instantaneous commutation (or a start from zero)
    st[S_PAIR] = pair
    st[S_PULSE] = 1.0
    st[S_GATE_END] = t + pa[P_TG] if pa[P_TG] > 0.0 else math.inf
    st[S_LATCH] = 1.0 if j > 0.0 and j >= pa[P_IL] else 0.0  # the incoming device's
    _log(st, log_row, t, pair, b, st[S_ALPHA])


@numba.njit(cache=True)
def _gate_end(pa, st):
    """The gate pulses of the pair end: a current that has not reached the latching current
    is interrupted (the thyristor does not stay on); a latched one flows on."""
    st[S_GATE_END] = math.inf
    st[S_PULSE] = 0.0
    if st[S_I] != 0.0 and st[S_LATCH] == 0.0 and pa[P_IL] > 0.0:
        st[S_I] = 0.0
        st[S_ZERO] = 1.0
        st[S_OVL] = 0.0


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
    elif pa[P_ANALOG] != 0.0:
        if active and analog.speed_output(pa, st, tacho, interval):
            v = firing.analog_current_regulator(pa, st, t, tacho)
            st[S_IMEAS] = st[S_IF]
            if v == v:
                alpha = firing.firing_angle(pa, table, v, st[S_BRIDGE] * pa[P_K] / pa[P_KC] * tacho)
        else:
            alpha = firing.block(pa, st)
    elif active and speed_regulator(pa, st, tacho, interval):
        v = firing.current_regulator(pa, st, t, i_meas, dcm, interval, tacho)
        if v == v:
            e_b = st[S_BRIDGE] * pa[P_K] / pa[P_KC] * tacho
            alpha = firing.firing_angle(pa, table, v, e_b)
    else:
        alpha = firing.block(pa, st)
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
        st[S_GATE_END] = math.inf
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
def _overlap_end(pa, st, p, dc, ds, w, h):
    """The end of the commutation overlap within [0, h] of a piece whose current is in
    ``p`` (−1 if none); (d_c, d_s) is u_in − u_out as a phasor. Leaves in ``p`` what
    :func:`_overlap_carry` needs."""
    if pa[P_RT] == 0.0:
        p[7], p[8], p[9], p[10], p[11] = dc, ds, pa[P_LC], st[S_OVL_J0], st[S_OVL_D]
        return first_root(KIND_COMMUTATION, p, h)
    # L_c·Δ' + r_T·Δ = u_in − u_out: its steady state (q_c, q_s) and τ_c = L_c/r_T
    qc, qs, _, _, tc = current_coeffs(dc, ds, 0.0, 0.0, pa[P_RT], pa[P_LC], w)
    p[7], p[8], p[9], p[10] = qc, qs, tc, st[S_OVL_D]
    return first_root(KIND_COMMUTATION_R, p, h)


@numba.njit(cache=True)
def _overlap_carry(pa, st, p, dc, ds, w, t):
    """The overlap's state at t into the piece: ∫(u_in − u_out) dt since it began (r_T = 0)
    or the branches' current difference Δ (r_T > 0, from ``p`` as :func:`_overlap_end`
    left it)."""
    wt = w * t
    if pa[P_RT] == 0.0:
        hh = math.sin(0.5 * wt)
        st[S_OVL_D] += (dc * math.sin(wt) + ds * 2.0 * hh * hh) / w
    else:
        qc, qs, tc, d0 = p[7], p[8], p[9], p[10]
        st[S_OVL_D] = qc * math.cos(wt) + qs * math.sin(wt) + (d0 - qc) * math.exp(-t / tc)


@numba.njit(cache=True)
def _split_charge(bins, s0, bin_w, b, q, t_end, j0, pc, ps, a, bb, tau, w):
    """Add the charge of a piece to each sub-step it spans (``bins`` of width ``bin_w``; the
    piece starts ``s0`` into the interval), from the closed form at their boundaries."""
    m = bins.shape[0]
    k = min(int(s0 / bin_w), m - 1)
    q_done = 0.0
    while k < m - 1 and (k + 1) * bin_w < s0 + t_end:
        q_k = charge((k + 1) * bin_w - s0, j0, pc, ps, a, bb, tau, w)
        bins[k] += b * max(q_k - q_done, 0.0)
        q_done = q_k
        k += 1
    bins[k] += b * max(q - q_done, 0.0)


@numba.njit(cache=True)
def _conduct(pa, st, p, t, h, e0, e1, bins, s0, bin_w):
    """Armature over [t, t + h] of the selected pair: returns (time advanced, charge in the
    motor's sense, conducting time). Stops early at an ignition, an extinction, the end of an
    overlap or the current reaching the latching current (the state then describes that
    instant). The charge is also added to ``bins``, split exactly at their boundaries.

    The circuit: L_eff·dj/dt = u(t) − b·E(t) − U_v − R_eff·j, U_v the constant drop of the
    brushes and the thyristor thresholds. A non-conducting pair starts only while its gate
    pulse is on; the current stops at zero while the gate pulse is on (a gated thyristor
    conducts however small its current) and below the holding current after it."""
    b = st[S_BRIDGE]
    j0 = b * st[S_I]
    pair = st[S_PAIR]
    w = pa[P_WM]
    gate = st[S_PULSE] != 0.0
    g0, g1 = -b * e0 - pa[P_UDROP], -b * e1
    vc, vs = _phasor(pa, t, pair)
    overlap = st[S_OVL] != 0.0
    if overlap:
        oc, os_ = _phasor(pa, t, pair - 1.0)
        dc, ds = vc - oc, vs - os_
        vc, vs = 0.5 * (vc + oc), 0.5 * (vs + os_)
    if j0 <= 0.0:  # not conducting: wait until the gated pair is forward biased
        if not gate or _reverse_biased_throughout(vc, vs, g0, g1, w, h):
            return h, 0.0, 0.0
        p[0], p[1], p[2], p[3], p[6] = vc, vs, g0, g1, w
        t_on = first_root(KIND_IGNITION, p, h)
        if t_on < 0.0:
            return h, 0.0, 0.0
        if t_on > 0.0:
            return t_on, 0.0, 0.0
        j0 = 0.0
    if overlap:  # the commutating group's two branches in parallel
        l_eff = pa[P_L] + (pa[P_NSER] - 0.5) * pa[P_LC]
        r_eff = pa[P_R] - 0.5 * pa[P_RT]
    else:
        l_eff = pa[P_L] + pa[P_NSER] * pa[P_LC]
        r_eff = pa[P_R]
    pc, ps, a, bb, tau = current_coeffs(vc, vs, g0, g1, r_eff, l_eff, w)
    i_off = 0.0 if gate else pa[P_IH]  # the current at which conduction ends
    p[0], p[1], p[2], p[3], p[4], p[5], p[6] = j0 - i_off, pc, ps, a - i_off, bb, tau, w
    t_end = h
    event = 0
    t_z = first_root(KIND_CURRENT, p, h)
    if t_z >= 0.0:
        t_end, event = t_z, 1
    if overlap:
        p[0], p[3] = j0, a
        t_c = _overlap_end(pa, st, p, dc, ds, w, t_end)
        if t_c >= 0.0 and (event == 0 or t_c < t_end):
            t_end, event = t_c, 2
    i_l = pa[P_IL]
    if i_l > 0.0 and gate and st[S_LATCH] == 0.0 and pa[P_TG] > 0.0:
        if j0 >= i_l:
            st[S_LATCH] = 1.0
        else:
            p[0], p[3] = j0 - i_l, a - i_l
            t_l = first_root(KIND_RISE, p, t_end)
            if t_l >= 0.0 and (event == 0 or t_l < t_end):
                t_end, event = t_l, 3
    if overlap:
        _overlap_carry(pa, st, p, dc, ds, w, t_end)
    q = charge(t_end, j0, pc, ps, a, bb, tau, w)
    _split_charge(bins, s0, bin_w, b, q, t_end, j0, pc, ps, a, bb, tau, w)
    if pa[P_ANALOG] != 0.0:  # the shunt's RC filter over the piece
        st[S_IF] = b * analog.filter_current(b * st[S_IF], t_end, j0, pc, ps, a, bb, tau, w,
                                             pa[P_TFI])
    if event == 1:
        st[S_I] = 0.0
        st[S_ZERO] = 1.0
        st[S_OVL] = 0.0
        st[S_LATCH] = 0.0
    else:
        st[S_I] = b * max(current_at(t_end, j0, pc, ps, a, bb, tau, w), 0.0)
        if event == 2:
            st[S_OVL] = 0.0
        elif event == 3:
            st[S_LATCH] = 1.0
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
    analog_on = pa[P_ANALOG] != 0.0
    while True:
        if st[S_FIRE_AT] <= t + _EPS:
            _fire(pa, st, t, log_row)
            continue
        if st[S_GATE_END] <= t + _EPS:
            _gate_end(pa, st)
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
        seg_end = min(st[S_NEXT], st[S_FIRE_AT], t_end, st[S_GATE_END])
        if seg_end > t_end - _EPS:
            seg_end = t_end
        h = seg_end - t
        s = t - t0
        w_t = w0 + slope * s
        e0 = pa[P_K] * w_t
        e1 = pa[P_K] * slope
        if st[S_BRIDGE] != 0.0 and (st[S_PULSE] != 0.0 or st[S_I] != 0.0):
            done, q, on = _conduct(pa, st, p, t, h, e0, e1, bins, s, bin_w)
        else:
            done, q, on = h, 0.0, 0.0
        if analog_on:
            st[S_QA] += q
            if on == 0.0:  # no current: the filter decays
                st[S_IF] *= math.exp(-done / pa[P_TFI]) if pa[P_TFI] > 0.0 else 0.0
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
    middle angle); an analog drive's regulators integrate over the same span."""
    s = t_a - t0
    h = t_b - t_a
    mid = s + 0.5 * h
    theta_mid = theta0 + w0 * mid + 0.5 * slope * mid * mid
    if pa[P_ANALOG] != 0.0:
        analog.advance(pa, st, active, u_in, w0 + slope * s, slope, theta_mid, h)
    else:
        advance_filters(pa, st, active, u_in, w0 + slope * s, slope, theta_mid, h)
