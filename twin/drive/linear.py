"""Continuous linear model of one axis drive with rigid mechanics (for the DCU derivation).

From the speed reference U (V) at the drive input to the table position x (m)::

    x/U = 1/(T1·s + 1) · G/(1 + G·H) · r/s

    G = K_pω·(T_iω·s + 1)/(T_iω·s) · 1/(T_ie·s + 1) · k/(J·s)     (forward path, V → rad/s)
    H = K_C/(T_f·s + 1)                                             (tacho feedback, V·s/rad)

with the constants of :func:`twin.drive.design.design` (the machine file's own regulator
settings where it gives them): the speed PI, the closed current loop, the tacho filter in the
feedback path and r the transmission ratio (m/rad). Its velocity gain is K_H = r/K_C (m/s
per V), the "K_M/K_C" of seed 000.

The closed current loop is the modulus optimum's equivalent first-order lag T_ie = 2·T_μ
while the current regulator is the designed one. Where the machine file sets it
(``regulators.current_kp`` or ``current_ti``), the loop is written out instead: the PI
K_pi·(T_ii·s + 1)/(T_ii·s) on the converter's dead time 1/(T_v·s + 1) (T_v = T_p/2) and the
armature 1/R/(T_a·s + 1), with the measurement's lag 1/(T_m·s + 1) in the feedback (T_m =
T_p/2 for the pulse mean, T_fi for the analog filter, 0 for the mean-value model):

    I/I* = F/(1 + F/(T_m·s + 1)),   F = K_pi·(T_ii·s + 1)/(T_ii·s) · 1/(T_v·s + 1) ·
           1/(R·(T_a·s + 1))
"""

from __future__ import annotations

import numpy as np

from twin.config import AxisConfig
from twin.drive.design import DriveDesign, design

__all__ = ["axis_transfer_function", "current_transfer_function", "speed_transfer_function",
           "velocity_gain"]


def _lag(t: float) -> np.ndarray:
    """Polynomial T·s + 1 (highest power first); just 1 when T = 0."""
    return np.array([t, 1.0]) if t > 0.0 else np.array([1.0])


def current_transfer_function(d: DriveDesign) -> tuple[np.ndarray, np.ndarray]:
    """Closed current loop from the current reference to the armature current (A/A), the
    regulator as set (see the module docstring; the EMF compensated).

    Returns
    -------
    num, den : ndarray
        Polynomial coefficients in s, highest power first; DC gain 1.
    """
    t_v = 0.5 * d.sampling_period
    if d.implementation == "analog":
        t_m = d.current_filter
    else:
        t_m = d.converter_time_constant - t_v   # T_p/2 (pulse mean) or 0 (mean model)
    num_f = d.current_kp * _lag(d.current_ti)
    den_f = np.polymul(np.polymul([d.current_ti, 0.0], _lag(t_v)),
                       d.resistance * _lag(d.armature_time_constant))
    num = np.polymul(num_f, _lag(t_m))
    den = np.polyadd(np.polymul(den_f, _lag(t_m)), num_f)
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
    d = design(axis, moving_mass=moving_mass)
    # G = num_g/den_g
    num_g = d.speed_kp * d.emf_constant * _lag(d.speed_ti)
    if d.current_regulator_designed:
        den_g = np.polymul([d.speed_ti, 0.0], np.polymul(_lag(d.current_loop_time_constant),
                                                         [d.inertia, 0.0]))
    else:
        num_i, den_i = current_transfer_function(d)
        num_g = np.polymul(num_g, num_i)
        den_g = np.polymul([d.speed_ti, 0.0], np.polymul(den_i, [d.inertia, 0.0]))
    # G/(1 + G·H) with H = K_C/(T_f s + 1)
    num = np.polymul(num_g, _lag(d.tacho_filter))
    den = np.polyadd(np.polymul(den_g, _lag(d.tacho_filter)), d.tacho_gain * num_g)
    den = np.polymul(den, _lag(d.reference_filter))
    return num / den[0], den / den[0]


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
