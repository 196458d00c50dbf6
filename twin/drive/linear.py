"""Continuous linear model of one axis drive with rigid mechanics (for the DCU derivation).

From the speed reference U (V) at the drive input to the table position x (m)::

    x/U = 1/(T1·s + 1) · G/(1 + G·H) · r/s

    G = K_pω·(T_iω·s + 1)/(T_iω·s) · 1/(T_ie·s + 1) · k/(J·s)     (forward path, V → rad/s)
    H = K_C/(T_f·s + 1)                                             (tacho feedback, V·s/rad)

with the constants of :func:`twin.drive.design.design` (the machine file's own regulator
settings where it gives them): the speed PI, the closed current loop, the tacho filter in the
feedback path and r the transmission ratio (m/rad). Its velocity gain is K_H = r/K_C (m/s
per V), the "K_M/K_C" of seed 000.

The closed current loop is a first-order lag T_ie: 2·T_μ for the modulus optimum, and where
the machine file sets the current regulator (``regulators.current_kp`` or ``current_ti``)
the first moment of the loop as set, T_ie = R·T_ii/K_pi (the closed loop of the PI
K_pi·(T_ii·s + 1)/(T_ii·s) on 1/R/(T_a·s + 1) and small lags is 1 − s·R·T_ii/K_pi + O(s²);
at the modulus optimum's settings that is 2·T_μ again). A lumped lag follows the sampled
pulse-level drive better than the loop written out with T_p/2 lags (its firing delay and
pulse mean are not such lags).
"""

from __future__ import annotations

import numpy as np

from twin.config import AxisConfig
from twin.drive.design import DriveDesign, design

__all__ = ["axis_transfer_function", "current_loop_lag", "speed_transfer_function",
           "velocity_gain"]


def _lag(t: float) -> np.ndarray:
    """Polynomial T·s + 1 (highest power first); just 1 when T = 0."""
    return np.array([t, 1.0]) if t > 0.0 else np.array([1.0])


def current_loop_lag(d: DriveDesign) -> float:
    """T_ie, the closed current loop's equivalent first-order lag (s): 2·T_μ for the
    designed regulator, R·T_ii/K_pi for the one the machine file sets."""
    if d.current_regulator_designed:
        return d.current_loop_time_constant
    return d.resistance * d.current_ti / d.current_kp


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
    den_g = np.polymul([d.speed_ti, 0.0], np.polymul(_lag(current_loop_lag(d)),
                                                     [d.inertia, 0.0]))
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
