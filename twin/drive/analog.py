"""The analog drive's regulators: continuous PI circuits between the converter's events
(numba, scalar; ``regulators.implementation = "analog"``).

A KEMEK-era drive builds its regulators of operational amplifiers set by potentiometers:

- the speed regulator, a PI circuit on e_ω = U_ref,f − U_tacho,f (the reference after its
  filter T1, the tacho after its filter T_f): i* = K_pω·e_ω + S_ω, dS_ω/dt = (K_pω/T_iω)·e_ω,
  its output limited to ±I_lim by the circuit's limiter;
- the current measured through a shunt and an RC filter T_fi:
  T_fi·di_f/dt = i(t) − i_f, i(t) the instantaneous armature current (pulses and all);
- the current regulator, a PI circuit on the current error:
  V_c = E_est + K_pi·(i* − i_f) + S_i, dS_i/dt = (K_pi/T_ii)·(i* − i_f), its output limited
  to the firing unit's range;
- the firing unit takes V_c at each firing instant and fires at α = arccos(V_c/U_d0) (no
  discontinuous-conduction adaptation: in discontinuous conduction the gain from V_c to the
  mean current collapses, and the loop's with it).

How the kernel integrates them. The filtered current is advanced over every piece of the
converter's event loop in closed form (:func:`filter_current`: the piece's current is the
closed form of :mod:`twin.drive.bridge`). The integrators are advanced at the firing unit's
read instants and at the end of each drive interval (:func:`advance`), spans of at most one
drive interval, with exact integrals of their inputs: a first-order filter y of input x has
∫y dt = ∫x dt − T·(y(t_b) − y(t_a)), so ∫e_ω dt and ∫i_f dt are exact (∫i dt is the
converter's exact charge). The speed regulator's output enters the current integrator as the
exact ∫K_pω·e_ω dt plus the trapezoidal rule on S_ω (S_ω changes over the speed loop's
integral time, tens of milliseconds). Anti-windup as the limiting circuits do it: an
integrator does not integrate further into its limit.
"""

from __future__ import annotations

import math

import numba

from twin.drive.layout import (
    P_EMFC,
    P_ILIM,
    P_K,
    P_KC,
    P_KPC,
    P_KPS,
    P_T1,
    P_TF,
    P_TFI,
    P_TIC,
    P_TIS,
    P_VHI,
    P_VLO,
    S_BRIDGE,
    S_CINT,
    S_IF,
    S_IFA,
    S_QA,
    S_REF,
    S_SINT,
    S_TACHO,
)
from twin.drive.loops import advance_filters, current_reference, ripple_factor

__all__ = ["advance", "filter_current", "speed_output"]


@numba.njit(cache=True)
def filter_current(y0, t, j0, pc, ps, a, b, tau, w, tf):
    """Output of the RC filter T_f·dy/dt = j(t) − y after time t, from y0, for the piece's
    current j(t) = p_c·cos(w·t) + p_s·sin(w·t) + A + B·t + (j0 − p_c − A)·e^{−t/τ}.

    Each term's forced response in closed form: the sinusoid through 1/(1 + j·w·T_f), the ramp
    A + B·(t − T_f), the exponential c·(e^{−t/τ} − e^{−t/T_f})/(1 − T_f/τ) (its limit
    c·(t/T_f)·e^{−t/T_f} when τ → T_f); then the free response from y0.
    """
    c = j0 - pc - a
    wt = w * t
    if tf <= 0.0:
        return pc * math.cos(wt) + ps * math.sin(wt) + a + b * t + c * math.exp(-t / tau)
    k = tf * w
    d = 1.0 + k * k
    yc = (pc - k * ps) / d
    ys = (ps + k * pc) / d
    ef = math.exp(-t / tf)
    delta = 1.0 / tf - 1.0 / tau
    x = delta * t
    if abs(x) > 1e-3:
        z = c / tf * (math.exp(-t / tau) - ef) / delta
    else:
        z = c / tf * t * ef * (1.0 + x * (0.5 + x / 6.0))
    return (yc * math.cos(wt) + ys * math.sin(wt) + a + b * (t - tf) + z
            + (y0 - yc - a + b * tf) * ef)


@numba.njit(cache=True)
def _clamp(x, lo, hi):
    return min(max(x, lo), hi)


@numba.njit(cache=True)
def advance(pa, st, active, u_in, w_a, slope, theta_mid, h):
    """Advance the reference and tacho filters and both PI integrators over a span of length
    h that starts at rotor speed w_a (rad/s) with slope dω/dt; the filtered current S_IF is
    already at the span's end and S_QA holds the span's charge (A·s)."""
    uf0, y0 = st[S_REF], st[S_TACHO]
    advance_filters(pa, st, active, u_in, w_a, slope, theta_mid, h)
    i_f = st[S_IF]
    int_if = st[S_QA] - pa[P_TFI] * (i_f - st[S_IFA])
    st[S_QA] = 0.0
    st[S_IFA] = i_f
    if not active:
        return
    uf1, y1 = st[S_REF], st[S_TACHO]
    f = ripple_factor(pa, theta_mid)
    int_e = (u_in * h - pa[P_T1] * (uf1 - uf0)
             - (pa[P_KC] * f * (w_a * h + 0.5 * slope * h * h) - pa[P_TF] * (y1 - y0)))
    kps, ilim = pa[P_KPS], pa[P_ILIM]
    e0, e1 = uf0 - y0, uf1 - y1
    sw0 = st[S_SINT]
    step = kps / pa[P_TIS] * int_e
    out = kps * e1 + sw0 + step
    if (out >= ilim and step > 0.0) or (out <= -ilim and step < 0.0):
        step = 0.0
    sw1 = _clamp(sw0 + step, -ilim, ilim)
    i0 = kps * e0 + sw0
    i1 = kps * e1 + sw1
    if abs(i0) < ilim and abs(i1) < ilim:
        int_iref = kps * int_e + 0.5 * h * (sw0 + sw1)
    else:
        int_iref = 0.5 * h * (_clamp(i0, -ilim, ilim) + _clamp(i1, -ilim, ilim))
    st[S_SINT] = sw1
    b = st[S_BRIDGE]
    if b == 0.0:
        return
    kpc = pa[P_KPC]
    ff = b * pa[P_K] / pa[P_KC] * y1 if pa[P_EMFC] != 0.0 else 0.0
    lo, hi = pa[P_VLO] - ff, pa[P_VHI] - ff
    ci = st[S_CINT]
    step = kpc / pa[P_TIC] * b * (int_iref - int_if)
    err1 = b * (_clamp(i1, -ilim, ilim) - i_f)
    out = kpc * err1 + ci + step
    if (out >= hi and step > 0.0) or (out <= lo and step < 0.0):
        step = 0.0
    if int_if * b <= 0.0 and step < 0.0:  # no current to lower: hold, do not wind
        step = 0.0
    st[S_CINT] = _clamp(ci + step, lo, hi)


@numba.njit(cache=True)
def speed_output(pa, st, tacho, interval):
    """The speed regulator's output now (A), tacho sample ``tacho`` (V): the current
    reference, limited; counts the time at the limit and trips the overload fault. Returns
    False if the drive just tripped."""
    i_lim = pa[P_ILIM]
    i_ref = _clamp(pa[P_KPS] * (st[S_REF] - tacho) + st[S_SINT], -i_lim, i_lim)
    return current_reference(pa, st, i_ref, interval)
