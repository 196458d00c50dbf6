"""Continuous linear model of one axis drive with rigid mechanics (for the DCU derivation).

From the speed reference U (V) at the drive input to the table position x (m)::

    x/U = 1/(T1·s + 1) · ω/U · r/s

    ω/U = G/(1 + G·K_C/(T_f·s + 1)),   G = K_pω·(T_iω·s + 1)/(T_iω·s) · k/(J·s) · I/I*

with the constants of :func:`twin.drive.design.design` (the machine file's own regulator
settings where it gives them): the speed PI, the tacho filter T_f in the feedback path, J
the inertia at the motor shaft and r the transmission ratio (m/rad). Its velocity gain is
K_H = r/K_C (m/s per V), the "K_M/K_C" of seed 000.

The current loop as built
    I/I* is the current loop written out, not a lumped lag: the PI
    C_i = K_pi·(T_ii·s + 1)/(T_ii·s) with its settings, the converter's dead time
    D = g/(T_v·s + 1), the armature circuit 1/(L·s + R) (R = R + n_d·r_T, L = L + L_s + n·L_c:
    the thyristors' slope resistance, the smoothing reactor, the commutating inductance),
    the current measurement M = 1/(T_m·s + 1) in the feedback, and the back-EMF k·ω
    compensated as the drive does it, by (k/K_C)·U_tacho, the *filtered* tacho, added to the
    regulator's output before the converter::

        (L·s + R)·I = D·(c·k·ω/(T_f·s + 1) + C_i·(I* − M·I)) − k·ω,   ω = k·I/(J·s)

    (c = 1 with the compensation, 0 without). So the loop is coupled to the mechanics: the
    compensation's residual k·ω·(1 − D/(T_f·s + 1)) is what the filter and the dead time let
    through. The small lags are those the design lumps into T_μ (:mod:`twin.drive.design`):

    ========================  ==============================  ====================
    drive                     T_v (dead time)                 T_m (measurement)
    ========================  ==============================  ====================
    digital, pulse level      T_p/2: sample and hold          T_p/2: pulse mean
    analog, pulse level       T_p/2: the firing unit's read   T_fi: shunt RC filter
    mean-value model, PWM     T_p/2: sample and hold          0: instantaneous
    ========================  ==============================  ====================

    g = 1 + ``converter.mains_deviation`` for a thyristor converter (its firing unit assumes
    the rated mains), 1 for PWM. At the modulus optimum's settings the loop is close to the
    design's lumped lag 2·T_μ; off them (a machine's own ``regulators``) only the written-out
    loop follows the drive (``tests/drive/test_linear.py``).

What the model stands for
    Small signals about an operating point in **continuous conduction**. The pulse-level
    converter conducts discontinuously at light load (the feed speeds of a lightly loaded
    table), where its gain from firing angle to mean current is nonlinear and, without the
    adaptation, tens of times lower (``twin/drive/README.md``); no linear model stands for
    that. The constant drops (brushes, thyristor thresholds) shift the operating point and
    do not enter; neither do the current limit, the reversal of the bridge pair and the
    firing unit's angle limits.
"""

from __future__ import annotations

from functools import reduce

import numpy as np

from twin.config import AxisConfig
from twin.drive.design import DriveDesign, design

__all__ = ["axis_transfer_function", "current_transfer_function", "speed_response",
           "speed_transfer_function", "velocity_gain"]


def _lag(t: float) -> np.ndarray:
    """Polynomial T·s + 1 (highest power first); just 1 when T = 0."""
    return np.array([t, 1.0]) if t > 0.0 else np.array([1.0])


def _mul(*polys) -> np.ndarray:
    """Product of polynomials (highest power first)."""
    return reduce(np.polymul, polys, np.array([1.0]))


def _small_lags(d: DriveDesign) -> tuple[float, float]:
    """(T_v, T_m): the converter's dead time and the current measurement's lag (s)."""
    t_v = 0.5 * d.sampling_period
    if d.implementation == "analog":
        return t_v, d.current_filter
    return t_v, d.converter_time_constant - t_v   # pulse mean T_p/2, or 0 (mean model)


def _current_loop(axis: AxisConfig, moving_mass: float | None
                  ) -> tuple[DriveDesign, np.ndarray, np.ndarray]:
    """(the design, q, den) with I/I* = q·(T_f·s + 1)/den (the module docstring's loop,
    cleared of fractions and of the common factor s)."""
    d = design(axis, moving_mass=moving_mass)
    conv = axis.converter
    mains_gain = 1.0 + conv.mains_deviation if conv.kind == "thyristor" else 1.0
    t_v, t_m = _small_lags(d)
    dv, dm, df = _lag(t_v), _lag(t_m), _lag(d.tacho_filter)
    j, k, tii = d.inertia, d.emf_constant, d.current_ti
    c = 1.0 if d.emf_compensation else 0.0
    pi_num = d.current_kp * mains_gain * _lag(tii)
    q = j * _mul(pi_num, dm)
    # the armature, the regulator through the measurement, the EMF left uncompensated
    armature = j * tii * _mul([1.0, 0.0], [d.inductance, d.resistance], dv, dm, df)
    regulator = j * _mul(pi_num, df)
    emf = k * k * tii * _mul(dm, np.polysub(_mul(dv, df), [c * mains_gain]))
    return d, q, np.polyadd(np.polyadd(armature, regulator), emf)


def current_transfer_function(axis: AxisConfig, *, moving_mass: float | None = None
                              ) -> tuple[np.ndarray, np.ndarray]:
    """Closed current loop from the current reference to the armature current (A/A), the
    rotor free (inertia J, no friction), as in the module docstring.

    Parameters are those of :func:`speed_transfer_function`.

    Returns
    -------
    num, den : ndarray
        Polynomial coefficients in s, highest power first, ``den[0] == 1``; DC gain 1 with
        the EMF compensation at the rated mains.
    """
    d, q, den = _current_loop(axis, moving_mass)
    num = np.polymul(q, _lag(d.tacho_filter))
    return num / den[0], den / den[0]


def speed_transfer_function(axis: AxisConfig, *, moving_mass: float | None = None
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Closed speed loop from reference (V) to motor speed (rad/s), reference filter included.

    Parameters
    ----------
    axis : AxisConfig
        The axis.
    moving_mass : float, optional
        Mass moved by the axis (kg), as in :func:`twin.drive.design.design`.

    Returns
    -------
    num, den : ndarray
        Polynomial coefficients in s, highest power first, ``den[0] == 1``. The DC gain
        num[-1]/den[-1] is 1/K_C.
    """
    d, q, den_i = _current_loop(axis, moving_mass)
    # G = K_pω·(T_iω s + 1)·k·q·(T_f s + 1)/(T_iω·J·s²·den_i); closing the loop through
    # K_C/(T_f s + 1) cancels the tacho filter's factor from the loop's denominator
    pi_q = d.speed_kp * d.emf_constant * _mul(_lag(d.speed_ti), q)
    num = np.polymul(pi_q, _lag(d.tacho_filter))
    den = np.polyadd(d.speed_ti * d.inertia * _mul([1.0, 0.0, 0.0], den_i), d.tacho_gain * pi_q)
    den = np.polymul(den, _lag(d.reference_filter))
    return num / den[0], den / den[0]


def speed_response(axis: AxisConfig, s: np.ndarray, admittance: np.ndarray, *,
                   moving_mass: float | None = None) -> np.ndarray:
    """The closed speed loop from reference (V) to motor speed (rad/s) at the complex
    frequencies ``s``, the rotor's mechanics given by its admittance Y(s) = ω/τ (rad/s per
    N·m) instead of the rigid 1/(J·s): the same loop as :func:`speed_transfer_function`
    (the module docstring's current loop, the speed PI, the tacho filter in the feedback,
    the reference filter), evaluated point by point, so that an elastic chain behind the
    rotor (its anti-resonances and resonances) enters as it is.

    Parameters
    ----------
    axis : AxisConfig
    s : ndarray, complex
        Laplace variable (1/s), non-zero.
    admittance : ndarray, complex, shape of ``s``
        Y(s) of the rotor with its load (rad/(s·N·m)).
    moving_mass : float, optional
        As in :func:`speed_transfer_function` (the regulators' design inertia).

    Returns
    -------
    ndarray, complex, shape of ``s``
        ω/U (rad/(s·V)); with Y = 1/(J·s) it is :func:`speed_transfer_function`.
    """
    d = design(axis, moving_mass=moving_mass)
    conv = axis.converter
    mains_gain = 1.0 + conv.mains_deviation if conv.kind == "thyristor" else 1.0
    t_v, t_m = _small_lags(d)
    s = np.asarray(s, dtype=complex)
    y = np.asarray(admittance, dtype=complex)
    dead = mains_gain / (t_v * s + 1.0)
    measure = 1.0 / (t_m * s + 1.0)
    tacho = 1.0 / (d.tacho_filter * s + 1.0)
    pi_i = d.current_kp * (d.current_ti * s + 1.0) / (d.current_ti * s)
    k = d.emf_constant
    c = 1.0 if d.emf_compensation else 0.0
    current = dead * pi_i / (d.inductance * s + d.resistance - dead * c * k * k * y * tacho
                             + dead * pi_i * measure + k * k * y)
    pi_w = d.speed_kp * (d.speed_ti * s + 1.0) / (d.speed_ti * s)
    forward = y * k * current * pi_w
    return forward / (d.reference_filter * s + 1.0) / (1.0 + forward * d.tacho_gain * tacho)


def axis_transfer_function(axis: AxisConfig, *, moving_mass: float | None = None
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Linear model from the speed reference (V) to the table position (m), rigid mechanics.

    Parameters are those of :func:`speed_transfer_function`.

    Returns
    -------
    num, den : ndarray
        Polynomial coefficients in s, highest power first, ``den[0] == 1``: the closed speed
        loop times r/s (one free integrator: ``den[-1] == 0``).
    """
    num, den = speed_transfer_function(axis, moving_mass=moving_mass)
    return num * axis.transmission.ratio, np.polymul(den, [1.0, 0.0])


def velocity_gain(axis: AxisConfig) -> float:
    """K_H = r/K_C: steady table speed per volt of speed reference (m/(s·V))."""
    return axis.transmission.ratio / axis.tacho.gain
