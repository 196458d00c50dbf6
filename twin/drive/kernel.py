"""The compiled update of all axis drives over one interval (numba).

State and parameters of every axis live in flat float64 rows (``state[axis, S_*]``,
``params[axis, P_*]``) so that one call of :func:`drive_step` advances all drives with scalar
loops and no allocation. :class:`twin.drive.Drives` owns the arrays; this module only knows
their layout.

Time inside an interval [t0, t0 + dt] is split at the converter's firing instants
t_j = j·T_p. At each firing instant the regulators sample (speed PI, bridge logic, current PI,
firing angle); between firing instants the converter's mean voltage u is constant. The rotor
speed is known at t0 only; inside the interval it is extrapolated linearly from the last two
values, ω(t) = ω(t0) + (ω(t0) − ω(t0 − dt))·(t − t0)/dt (``P_EXTRAP`` = 1; 0 holds ω(t0)),
which makes the coupling to the mechanics second-order accurate in dt instead of delaying
the EMF and the tacho by dt/2. The armature equation and both first-order filters are then
solved exactly (:mod:`twin.drive.armature`), and the average torque over the interval is k
times the exact charge ∫i dt divided by dt.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from twin.drive.armature import armature_segment, first_order

__all__ = [
    "NP",
    "NS",
    "STATUS_NONFINITE_OMEGA",
    "STATUS_NONFINITE_RESULT",
    "STATUS_NONFINITE_UREF",
    "STATUS_OK",
    "drive_step",
    "empty_state",
]

# parameter columns (per axis)
P_R = 0          # armature resistance (Ω)
P_TA = 1         # armature time constant L/R (s)
P_K = 2          # EMF / torque constant (V·s/rad)
P_KC = 3         # tacho gain (V·s/rad)
P_TF = 4         # tacho filter (s)
P_T1 = 5         # reference filter (s)
P_KPS = 6        # speed PI gain (A/V)
P_TIS = 7        # speed PI integral time (s)
P_KPC = 8        # current PI gain (V/A)
P_TIC = 9        # current PI integral time (s)
P_ILIM = 10      # current limit (A)
P_TP = 11        # firing / PWM period (s)
P_UMAX = 12      # U_d0 or U_dc (V)
P_VLO = 13       # lowest mean voltage of the forward converter (V)
P_VHI = 14       # highest mean voltage of the forward converter (V)
P_PWM = 15       # 1: PWM converter, 0: thyristor bridge pair
P_PAUSE = 16     # reversal pause (s)
P_ITH = 17       # bridge selection threshold (A)
P_EMFC = 18      # 1: EMF compensation in the current regulator
P_NOISE = 19     # tacho noise rms (V)
P_OVERLOAD = 20  # time at the current limit that trips the fault (s)
P_EXTRAP = 21    # 1: extrapolate ω linearly inside the interval, 0: hold ω(t0)
NP = 22

# state columns (per axis)
S_I = 0          # armature current (A)
S_REF = 1        # filtered speed reference (V)
S_TACHO = 2      # filtered tacho voltage, noise-free (V)
S_SINT = 3       # speed PI integrator (A)
S_CINT = 4       # current PI integrator (V)
S_IREF = 5       # current reference (A)
S_V = 6          # converter mean output voltage (V)
S_ALPHA = 7      # firing angle (rad), NaN when blocked or PWM
S_BRIDGE = 8     # +1 forward, −1 reverse, 0 blocked
S_DIR = 9        # conduction constraint: +1 / −1 unidirectional, 0 free (PWM)
S_PAUSE_END = 10  # earliest time a bridge may be released (s)
S_FIRE = 11      # index j of the next firing instant j·T_p
S_SAT = 12       # time the current reference has been at its limit (s)
S_FAULT = 13     # 1: tripped
S_ADC = 14       # tacho voltage as the ADC reads it at the end of the interval (V)
S_TORQUE = 15    # average torque over the last interval (N·m)
S_WPREV = 16     # rotor speed given at the previous update (rad/s), NaN after a reset
NS = 17

STATUS_OK = 0
STATUS_NONFINITE_UREF = 1
STATUS_NONFINITE_OMEGA = 2
STATUS_NONFINITE_RESULT = 3

_EPS = 1e-12


@numba.njit(cache=True)
def _pi(error, integ, kp, t_ratio, lo, hi, freeze):
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
def _block(st):
    """Converter disabled: regulators reset; a flowing current is forced to zero."""
    st[S_SINT] = 0.0
    st[S_CINT] = 0.0
    st[S_IREF] = 0.0
    st[S_SAT] = 0.0
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
def _fire(pa, st, t, active, tacho):
    """Regulator action at a firing instant t: speed PI, bridge logic, current PI, angle."""
    pwm = pa[P_PWM] != 0.0
    t_p = pa[P_TP]
    if active:
        i_lim = pa[P_ILIM]
        i_ref, st[S_SINT] = _pi(st[S_REF] - tacho, st[S_SINT], pa[P_KPS], t_p / pa[P_TIS],
                                -i_lim, i_lim, False)
        st[S_IREF] = i_ref
        st[S_SAT] = st[S_SAT] + t_p if abs(i_ref) >= i_lim else 0.0
        if st[S_SAT] >= pa[P_OVERLOAD]:
            st[S_FAULT] = 1.0
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
    v, st[S_CINT] = _pi(error, st[S_CINT], pa[P_KPC], t_p / pa[P_TIC], lo - ff, hi - ff, freeze)
    v += ff
    st[S_V] = v
    st[S_ALPHA] = math.nan if pwm else math.acos(min(max(b * v / pa[P_UMAX], -1.0), 1.0))


@numba.njit(cache=True)
def drive_step(params, state, u_ref, omega, noise, n_step, dt, enabled, torque):
    """Advance every axis drive over [n_step·dt, (n_step + 1)·dt].

    Parameters
    ----------
    params : ndarray, shape (n, NP)
        Per-axis constants (columns ``P_*``).
    state : ndarray, shape (n, NS)
        Per-axis state (columns ``S_*``), updated in place.
    u_ref : ndarray, shape (n,)
        Speed reference at the drive input (V), constant over the interval.
    omega : ndarray, shape (n,)
        Rotor speed at the start of the interval (rad/s).
    noise : ndarray, shape (n, m)
        Standard normal samples for the tacho noise (scaled by ``P_NOISE``); m must exceed
        the number of firing instants in one interval.
    n_step : int
        Index of the interval (its start time is n_step·dt).
    dt : float
        Interval length (s).
    enabled : bool
        The drive enable input.
    torque : ndarray, shape (n,)
        Output: average motor torque over the interval (N·m), also kept in the state.

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
        t_p = pa[P_TP]
        k_noise = 0
        charge = 0.0
        t = t0
        while True:
            t_fire = st[S_FIRE] * t_p
            if t_fire <= t + _EPS:
                tacho = st[S_TACHO] + sigma * noise[a, k_noise]
                k_noise += 1
                _fire(pa, st, t, active, tacho)
                st[S_FIRE] += 1.0
                continue
            seg_end = t_fire if t_fire < t_end - _EPS else t_end
            h = seg_end - t
            w_t = w + slope * (t - t0)
            st[S_REF] = first_order(st[S_REF], u_in, 0.0, h, pa[P_T1]) if active else 0.0
            st[S_TACHO] = first_order(st[S_TACHO], pa[P_KC] * w_t, pa[P_KC] * slope, h,
                                      pa[P_TF])
            if st[S_BRIDGE] != 0.0 or st[S_I] != 0.0:
                st[S_I], q = armature_segment(st[S_I], st[S_V], pa[P_K] * w_t, pa[P_K] * slope,
                                              pa[P_R], pa[P_TA], h, st[S_DIR])
                charge += q
            t = seg_end
            if seg_end == t_end:
                break
        st[S_ADC] = st[S_TACHO] + sigma * noise[a, k_noise]
        st[S_TORQUE] = pa[P_K] * charge / dt
        torque[a] = st[S_TORQUE]
        if not (math.isfinite(st[S_TORQUE]) and math.isfinite(st[S_I])):
            return 1000 * STATUS_NONFINITE_RESULT + a
    return STATUS_OK


def empty_state(n: int) -> np.ndarray:
    """Zero state of n axes at time 0: blocked bridges, first firing instant at t = 0."""
    state = np.zeros((n, NS))
    state[:, S_ALPHA] = np.nan
    state[:, S_PAUSE_END] = -np.inf
    state[:, S_WPREV] = np.nan
    return state
