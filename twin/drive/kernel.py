"""The compiled update of all axis drives over one interval (numba).

State and parameters of every axis live in flat float64 rows (``state[axis, S_*]``,
``params[axis, P_*]``, columns named in :mod:`twin.drive.layout`) so that one call of
:func:`drive_step` advances all drives with scalar loops and no allocation.
:class:`twin.drive.Drives` owns the arrays.

Two converter models share the interval loop:

- the **pulse-level** thyristor converter (``P_MODEL`` = 1, :mod:`twin.drive.pulse`): the
  instantaneous voltage of the conducting pair, firing instants synchronised to the mains,
  conduction that stops at zero current and restarts at a firing, every event located
  exactly;
- the **mean-value** converter (``P_MODEL`` = 0): PWM, or a thyristor bridge averaged over
  each firing period. Time inside an interval [t0, t0 + dt] is split at the firing
  instants t_j = j·T_p. At each the regulators sample (speed PI, bridge logic, current PI,
  firing angle); between them the converter's mean voltage u is constant and the armature
  equation is solved exactly (:mod:`twin.drive.armature`).

In both, the rotor speed is known at t0 only; inside the interval it is extrapolated
linearly from the last two values, ω(t) = ω(t0) + (ω(t0) − ω(t0 − dt))·(t − t0)/dt
(``P_EXTRAP`` = 1; 0 holds ω(t0)), which makes the coupling to the mechanics second-order
accurate in dt instead of delaying the EMF and the tacho by dt/2. The average torque over
the interval is k times the exact charge ∫i dt divided by dt.
"""

from __future__ import annotations

import math

import numba

from twin.drive.armature import armature_segment
from twin.drive.layout import (
    NLOG,
    NP,
    NS,
    P_EMFC,
    P_EXTRAP,
    P_ITH,
    P_K,
    P_KC,
    P_KPC,
    P_LM,
    P_MAINS,
    P_MODEL,
    P_NOISE,
    P_PAUSE,
    P_PWM,
    P_R,
    P_RM,
    P_TA,
    P_TIC,
    P_TP,
    P_UB,
    P_UDROP,
    P_UMAX,
    P_VHI,
    P_VLO,
    S_ADC,
    S_ALPHA,
    S_BRIDGE,
    S_CINT,
    S_CONDUCT,
    S_DIR,
    S_FAULT,
    S_FIRE,
    S_I,
    S_IREF,
    S_PAUSE_END,
    S_TACHO,
    S_TORQUE,
    S_V,
    S_VOUT,
    S_WPREV,
    empty_state,
)
from twin.drive.loops import advance_filters, pi_step, reset_regulators, speed_regulator
from twin.drive.pulse import advance_pulse

__all__ = [
    "NLOG",
    "NP",
    "NS",
    "STATUS_NONFINITE_OMEGA",
    "STATUS_NONFINITE_RESULT",
    "STATUS_NONFINITE_UREF",
    "STATUS_OK",
    "drive_step",
    "empty_state",
]

STATUS_OK = 0
STATUS_NONFINITE_UREF = 1
STATUS_NONFINITE_OMEGA = 2
STATUS_NONFINITE_RESULT = 3

_EPS = 1e-12


@numba.njit(cache=True)
def _block(st):
    """Converter disabled: regulators reset; a flowing current is forced to zero."""
    reset_regulators(st)
    i = st[S_I]
    if i == 0.0:
        st[S_BRIDGE] = 0.0
        st[S_DIR] = 0.0
        return False
    b = 1.0 if i > 0.0 else -1.0
    st[S_BRIDGE] = b
    st[S_DIR] = b
    return True


@numba.njit(cache=True)
def _fire_mean(pa, st, t, active, tacho):
    """Mean-value model, at a firing instant t: speed PI, bridge logic, current PI, angle."""
    pwm = pa[P_PWM] != 0.0
    t_p = pa[P_TP]
    if active and not speed_regulator(pa, st, tacho, t_p):
        active = False
    if not active:
        if _block(st):  # pulses at the inverter end stop (bridge) / freewheeling (PWM)
            b = st[S_BRIDGE]
            st[S_V] = b * pa[P_VLO]
            st[S_ALPHA] = math.acos(pa[P_VLO] / pa[P_UMAX]) if not pwm else math.nan
        else:
            st[S_V] = 0.0
            st[S_ALPHA] = math.nan
        return
    i = st[S_I]
    i_ref = st[S_IREF]
    b = 1.0 if pwm else st[S_BRIDGE]
    e_est = pa[P_K] / pa[P_KC] * tacho
    ff = e_est if pa[P_EMFC] != 0.0 else 0.0
    if not pwm:  # logic switching unit of the non-circulating bridge pair
        if b == 0.0:
            if t >= st[S_PAUSE_END] - _EPS and abs(i_ref) > pa[P_ITH]:
                b = 1.0 if i_ref > 0.0 else -1.0
                st[S_CINT] = e_est - ff  # start at the EMF balance: no current surge
        elif b * i_ref < -pa[P_ITH] and i == 0.0:
            b = 0.0  # zero current confirmed: remove pulses, let the thyristors recover
            st[S_PAUSE_END] = t + pa[P_PAUSE]
            st[S_CINT] = 0.0
    st[S_BRIDGE] = b
    if b == 0.0:
        st[S_DIR] = 0.0
        st[S_V] = 0.0
        st[S_ALPHA] = math.nan
        return
    st[S_DIR] = 0.0 if pwm else b
    if b > 0.0:
        lo, hi = pa[P_VLO], pa[P_VHI]
    else:
        lo, hi = -pa[P_VHI], -pa[P_VLO]
    error = i_ref - i
    # a bridge that is not conducting cannot follow a demand of the other sign: hold the
    # integrator instead of winding it to the end stop (the dead zone of the reversal)
    freeze = (not pwm) and i == 0.0 and b * error < 0.0
    v, st[S_CINT] = pi_step(error, st[S_CINT], pa[P_KPC], t_p / pa[P_TIC], lo - ff, hi - ff,
                            freeze)
    v += ff
    st[S_V] = v
    st[S_ALPHA] = math.nan if pwm else math.acos(min(max(b * v / pa[P_UMAX], -1.0), 1.0))


@numba.njit(cache=True)
def _advance_mean(pa, st, t0, t_end, w0, slope, theta0, active, u_in, sigma, noise_row,
                  bins):
    """Advance one axis with the mean-value converter over [t0, t_end]; returns ∫i dt and
    gives every sub-step in ``bins`` the interval's average: the mean voltage is held over
    whole firing periods and the current changes smoothly with T_a, so the interval average
    is what the mechanics needs (and splitting at the sub-steps would only cost time)."""
    t_p = pa[P_TP]
    k_noise = 0
    charge = 0.0
    on = 0.0
    t = t0
    while True:
        t_fire = st[S_FIRE] * t_p
        if t_fire <= t + _EPS:
            tacho = st[S_TACHO] + sigma * noise_row[k_noise]
            k_noise += 1
            _fire_mean(pa, st, t, active, tacho)
            st[S_FIRE] += 1.0
            continue
        seg_end = t_fire if t_fire < t_end - _EPS else t_end
        h = seg_end - t
        s = t - t0
        w_t = w0 + slope * s
        theta_mid = theta0 + w0 * (s + 0.5 * h) + 0.5 * slope * (s + 0.5 * h) ** 2
        advance_filters(pa, st, active, u_in, w_t, slope, theta_mid, h)
        if st[S_BRIDGE] != 0.0 or st[S_I] != 0.0:
            st[S_I], q = armature_segment(st[S_I], st[S_V] * pa[P_MAINS], pa[P_K] * w_t,
                                          pa[P_K] * slope, pa[P_R], pa[P_TA], h, st[S_DIR],
                                          pa[P_UDROP])
            charge += q
            if q != 0.0:
                on += h
        t = seg_end
        if seg_end == t_end:
            break
    st[S_CONDUCT] = on / (t_end - t0)
    share = charge / bins.shape[0]
    for j in range(bins.shape[0]):
        bins[j] = share
    return charge


@numba.njit(cache=True)
def drive_step(params, state, tables, u_ref, omega, theta, noise, log, n_step, dt, enabled,
               torque, sub_torque, scratch):
    """Advance every axis drive over [n_step·dt, (n_step + 1)·dt].

    Parameters
    ----------
    params : ndarray, shape (n, NP)
        Per-axis constants (columns ``P_*``).
    state : ndarray, shape (n, NS)
        Per-axis state (columns ``S_*``), updated in place.
    tables : ndarray, shape (n, N_EMF, N_ALPHA)
        Each axis' discontinuous-conduction characteristic (:func:`twin.drive.dcm.
        build_table`; used by the pulse-level model with DCM compensation).
    u_ref : ndarray, shape (n,)
        Speed reference at the drive input (V), constant over the interval.
    omega : ndarray, shape (n,)
        Rotor speed at the start of the interval (rad/s).
    theta : ndarray, shape (n,)
        Rotor angle at the start of the interval (rad): phases the tacho ripple.
    noise : ndarray, shape (n, m)
        Standard normal samples for the tacho noise (scaled by ``P_NOISE``); m must exceed
        the number of regulator samples in one interval.
    log : ndarray, shape (n, k, NLOG)
        Firing log of the pulse-level model (time, pair, bridge, angle), filled up to k
        entries per axis (``S_NLOG`` counts them); k = 0 logs nothing.
    n_step : int
        Index of the interval (its start time is n_step·dt).
    dt : float
        Interval length (s).
    enabled : bool
        The drive enable input.
    torque : ndarray, shape (n,)
        Output: average motor torque over the interval (N·m), also kept in the state.
    sub_torque : ndarray, shape (n, m)
        Output: average motor torque over each of m equal sub-steps of the interval (N·m):
        what the mechanics' m physics steps get (the pulse-level converter's torque comes
        in pulses, which one interval average would alias).
    scratch : ndarray, shape (12,)
        Work space of the root finder (no allocation per call).

    Returns
    -------
    int
        ``STATUS_OK``, or ``1000·code + axis`` with code ``STATUS_NONFINITE_*``; on a
        non-finite input nothing is changed.
    """
    n = params.shape[0]
    for a in range(n):
        if not math.isfinite(u_ref[a]):
            return 1000 * STATUS_NONFINITE_UREF + a
        if not math.isfinite(omega[a]):
            return 1000 * STATUS_NONFINITE_OMEGA + a
    t0 = n_step * dt
    t_end = (n_step + 1) * dt
    for a in range(n):
        pa = params[a]
        st = state[a]
        active = enabled and st[S_FAULT] == 0.0
        w = omega[a]
        slope = 0.0  # dω/dt assumed over the interval (rad/s²)
        if pa[P_EXTRAP] != 0.0 and math.isfinite(st[S_WPREV]):
            slope = (w - st[S_WPREV]) / dt
        st[S_WPREV] = w
        sigma = pa[P_NOISE]
        u_in = u_ref[a] if active else 0.0
        th = theta[a] if math.isfinite(theta[a]) else 0.0
        i_start = st[S_I]
        bins = sub_torque[a]
        bins[:] = 0.0
        if pa[P_MODEL] != 0.0:
            q = advance_pulse(pa, st, tables[a], t0, t_end, w, slope, th, active, u_in,
                              sigma, noise[a], log[a], scratch, bins)
        else:
            q = _advance_mean(pa, st, t0, t_end, w, slope, th, active, u_in, sigma, noise[a],
                              bins)
        scale = pa[P_K] * bins.shape[0] / dt
        for j in range(bins.shape[0]):
            bins[j] *= scale
        # mean motor terminal voltage over the interval: R·i + L·di/dt + E integrated (it is
        # the EMF while no current flows), exact for both models; the motor's own R and L
        # (a smoothing reactor and the thyristors lie outside its terminals)
        st[S_VOUT] = ((pa[P_RM] * q + pa[P_LM] * (st[S_I] - i_start)) / dt
                      + pa[P_K] * (w + 0.5 * slope * dt))
        if pa[P_UB] != 0.0 and q != 0.0:  # the brushes' drop while current flowed
            st[S_VOUT] += math.copysign(pa[P_UB], q) * st[S_CONDUCT]
        st[S_ADC] = st[S_TACHO] + sigma * noise[a, noise.shape[1] - 1]
        st[S_TORQUE] = pa[P_K] * q / dt
        torque[a] = st[S_TORQUE]
        if not (math.isfinite(st[S_TORQUE]) and math.isfinite(st[S_I])):
            return 1000 * STATUS_NONFINITE_RESULT + a
    return STATUS_OK
