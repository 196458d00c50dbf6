"""Column layout of the drives' flat arrays (``params[axis, P_*]``, ``state[axis, S_*]``).

The compiled kernel (:mod:`twin.drive.kernel`, :mod:`twin.drive.pulse`) works on one row of
parameters and one row of state per axis, so that one call advances every drive with scalar
loops and no allocation. This module only names the columns; :class:`twin.drive.Drives`
fills them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NLOG", "NP", "NRIPPLE", "NS", "empty_state"]

# ----------------------------------------------------------------- parameters (per axis)
P_R = 0          # armature circuit resistance R_eff = R + n_d·r_T (Ω)
P_TA = 1         # armature time constant L_eff/R_eff (s)
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
P_MODEL = 22     # 0: mean-value converter (PWM, or the averaged bridge); 1: pulse level
P_UHAT = 23      # peak of the voltage one conducting pair applies, Û (V)
P_WM = 24        # mains angular frequency (rad/s)
P_PN = 25        # pulse number p (3 or 6)
P_L = 26         # armature circuit inductance without the line's, L + L_s (H)
P_LC = 27        # line (commutating) inductance per phase (H)
P_NSER = 28      # line inductances in series with a conducting pair (2 bridge, 1 midpoint)
P_DCMC = 29      # 1: the current regulator adapts to discontinuous conduction
P_AMIN = 30      # lowest firing angle (rad)
P_AMAX = 31      # highest firing angle, the inverter end stop (rad)
P_ALPHA_FIX = 32  # NaN: regulated; else fire the forward bridge at this angle (rad)
P_DCMG = 33      # per-pulse integral gain of the discontinuous-mode current regulator (1)
P_RIPPLE = 34    # NRIPPLE pairs (harmonic per revolution, amplitude as a fraction)
NRIPPLE = 4
P_T0 = P_RIPPLE + 2 * NRIPPLE  # time of natural commutation point 0 (s): the mains phase
P_UREAL = P_T0 + 1   # Û the circuit applies: the firing unit's Û times (1 + mains deviation)
P_MAINS = P_T0 + 2   # mean model: 1 + mains deviation (the applied U_d0 over the commanded)
P_UDROP = P_T0 + 3   # constant drop while current flows: brushes + n_d thresholds (V)
P_RT = P_T0 + 4      # slope resistance of one thyristor (Ω): the overlap's current split
P_IH = P_T0 + 5      # holding current (A): conduction without gate current ends below it
P_IL = P_T0 + 6      # latching current (A): needed by the end of the gate pulse
P_TG = P_T0 + 7      # gate pulse width (s); 0: on until the next firing
P_RM = P_T0 + 8      # the motor's own armature resistance (Ω): its terminal voltage
P_LM = P_T0 + 9      # the motor's own armature inductance (H): its terminal voltage
P_UB = P_T0 + 10     # brush drop (V): part of the motor's terminal voltage
P_ANALOG = P_T0 + 11  # 1: continuous (analog) regulators, 0: sampled (digital)
P_TFI = P_T0 + 12    # analog: RC filter on the measured current (s)
NP = P_T0 + 13

# ----------------------------------------------------------------- state (per axis)
S_I = 0          # armature current (A)
S_REF = 1        # filtered speed reference (V)
S_TACHO = 2      # filtered tacho voltage, noise-free (V)
S_SINT = 3       # speed PI integrator (A)
S_CINT = 4       # current regulator integrator (V)
S_IREF = 5       # current reference (A)
S_V = 6          # converter mean output voltage commanded (V): b·U_d0·cos α for a bridge
S_ALPHA = 7      # firing angle (rad), NaN when blocked or PWM
S_BRIDGE = 8     # +1 forward, −1 reverse, 0 blocked
S_DIR = 9        # mean model: conduction constraint +1 / −1 unidirectional, 0 free (PWM)
S_PAUSE_END = 10  # earliest time a bridge may be released (s)
S_FIRE = 11      # mean model: index j of the next firing instant j·T_p
S_SAT = 12       # time the current reference has been at its limit (s)
S_FAULT = 13     # 1: tripped
S_ADC = 14       # tacho voltage as the ADC reads it at the end of the interval (V)
S_TORQUE = 15    # average torque over the last interval (N·m)
S_WPREV = 16     # rotor speed given at the previous update (rad/s), NaN after a reset
S_J = 17         # pulse model: index of the next natural commutation point to sample
S_NEXT = 18      # pulse model: time of the next regulator sample (s)
S_FIRE_AT = 19   # pulse model: time of the pending firing (s), inf if none
S_FIRE_J = 20    # pulse model: pair of the pending firing
S_PAIR = 21      # pulse model: pair whose gate pulses are on (the conducting pair)
S_PULSE = 22     # pulse model: 1 while the gate pulses of S_PAIR are on
S_OVL = 23       # pulse model: 1 during a commutation overlap into S_PAIR
S_OVL_J0 = 24    # current when the overlap began (A, conducting sense)
S_OVL_D = 25     # ∫(u_in − u_out) dt since the overlap began (V·s)
S_Q = 26         # charge since the last regulator sample (A·s)
S_TLAST = 27     # time of the last regulator sample (s)
S_ZERO = 28      # 1: the current was zero at some instant since the last sample
S_MODE = 29      # current regulator: 0 continuous-conduction PI, 1 discontinuous mode
S_VOUT = 30      # mean motor terminal voltage over the last interval (V)
S_CONDUCT = 31   # fraction of the last interval with current flowing (1)
S_IMEAS = 32     # current the current regulator last measured (A): the pulse mean
S_ALAST = 33     # last firing angle scheduled (rad): times the next sample
S_NLOG = 34      # entries written to the firing log
S_GATE_END = 35  # pulse model: time the gate pulses of S_PAIR end (s), inf: at the next firing
S_LATCH = 36     # pulse model: 1 once the flowing current has reached the latching current
S_IF = 37        # analog: the current through the measurement filter (A)
S_IFA = 38       # analog: S_IF when the regulators were last advanced (A)
S_QA = 39        # analog: charge since the regulators were last advanced (A·s)
NS = 40

NLOG = 4
"""Fields of one firing-log entry: time (s), pair index, bridge (±1; 0: the gate pulses were
removed), firing angle (rad; NaN when removed)."""


def empty_state(n: int) -> np.ndarray:
    """Zero state of n axes at time 0: blocked bridges, first sample at t = 0."""
    state = np.zeros((n, NS))
    state[:, S_ALPHA] = np.nan
    state[:, S_PAUSE_END] = -np.inf
    state[:, S_WPREV] = np.nan
    state[:, S_FIRE_AT] = np.inf
    state[:, S_ALAST] = 0.5 * np.pi
    state[:, S_NEXT] = 0.0
    state[:, S_GATE_END] = np.inf
    return state
