"""Corner accuracy model: how fast may the tool pass a node and stay within tolerance.

Seed 001 (laser-cutting dissertation) found by simulation of the reduced axis model
W(s) = 1/((T·s + 1)(τ²s² + 2ξτs + 1)) that the maximum contour error δ_max near a node B
between two straight segments is linear in the node speed V_B and in |sin α|, so the
*relative* error δ* = δ_max / V_B (s) depends only on the corner angle and the dynamics:

    δ* = f1(α) · (|ξ_min − 0.25| + 0.25) · f2(dynamics),
    f1(α) = |sin α| for |α| < π/2, 1 for π/2 ≤ |α| ≤ π,

and the node speed that keeps the error within δ_allowed is V_node = δ_allowed / δ*.

α is the deflection angle at the node: the angle between the incoming and the outgoing
tangent (0 = straight through, π = reversal). ξ_min is the damping ratio of the axis with
the lowest mechanical natural frequency ω_min.

The dynamics factor f2 is illegible in the scanned source. This module makes it an explicit,
documented function of the closed servo-drive time constant T and the lowest mechanical
natural frequency ω_min,

    f2 = c · (T + 1/ω_min),

i.e. the lag of the servo plus the lag of the elastic mechanics, times a calibration constant
``c``. The default ``c`` = 1.272 makes the model exact for a rigid machine (ω_min → ∞) whose
servo is a first-order lag T, at the seed's study point ξ = 0.4 and a 90° corner: for that
system the seed's error measure (max of the distance to the two segments and of the closest
approach to the node) is exactly 0.5089·V·T (computed analytically: the closest approach
min_u √(e^(−2u) + (u − 1 + e^(−u))²) = 0.5089 at u = 0.879), and 0.5089 / 0.4 = 1.272.
Issue 5 fits ``c`` (and, if needed, T) to the twin by simulated corners; until then the
model is as good as that rigid-lag calibration.

Any object with ``max_node_speed(angle, tolerance) -> float`` can replace the model
(``CornerModel`` protocol), e.g. a table measured on the real machine.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from twin.config import AxisConfig, MachineConfig, moving_masses
from twin.errors import ConfigError

__all__ = [
    "RIGID_LAG_CORNER_ERROR",
    "CornerModel",
    "NoCornerLimit",
    "SeedCornerModel",
    "angle_factor",
    "damping_factor",
]

RIGID_LAG_CORNER_ERROR = 0.5088630061880719
"""Seed-001 corner error δ_max/(V·T) of a first-order lag T at a 90° corner (1)."""

_DEFAULT_CALIBRATION = RIGID_LAG_CORNER_ERROR / 0.4


@runtime_checkable
class CornerModel(Protocol):
    """The pluggable corner accuracy model of the planner."""

    def max_node_speed(self, angle: float, tolerance: float) -> float:
        """Largest node speed (m/s) that keeps the contour error within ``tolerance``.

        Parameters
        ----------
        angle : float
            Deflection angle between the incoming and outgoing tangents (rad), 0 … π.
        tolerance : float
            Allowed contour error δ_allowed (m).

        Returns
        -------
        float
            Node speed limit (m/s); ``math.inf`` when the corner costs no accuracy.
        """
        ...


def angle_factor(angle: float) -> float:
    """Seed 001 f1(α): |sin α| for |α| < π/2, else 1 (1)."""
    a = abs(angle)
    return math.sin(a) if a < 0.5 * math.pi else 1.0


def damping_factor(damping_ratio: float) -> float:
    """Seed 001 damping factor |ξ − 0.25| + 0.25 (1)."""
    return abs(damping_ratio - 0.25) + 0.25


@dataclass(frozen=True)
class SeedCornerModel:
    """Seed 001 corner model δ* = f1(α)·(|ξ−0.25|+0.25)·c·(T + 1/ω_min).

    Parameters
    ----------
    servo_time_constant : float
        T, the time constant of the closed servo drive / position loop (s). Seed 001: 0.01.
    natural_frequency : float
        ω_min, the lowest mechanical natural frequency of the axes (rad/s); ``math.inf`` for
        rigid mechanics.
    damping_ratio : float
        ξ_min, the damping ratio of the mode at ω_min (1). Seed 001: 0.4.
    calibration : float
        c, the calibration constant of the dynamics factor (1); see the module docstring.
    """

    servo_time_constant: float = 0.01
    natural_frequency: float = math.inf
    damping_ratio: float = 0.4
    calibration: float = _DEFAULT_CALIBRATION

    def __post_init__(self) -> None:
        if not (math.isfinite(self.servo_time_constant) and self.servo_time_constant >= 0):
            raise ConfigError("servo_time_constant",
                              f"must be finite and >= 0 (s), got {self.servo_time_constant}")
        if not self.natural_frequency > 0:
            raise ConfigError("natural_frequency",
                              f"must be > 0 (rad/s), got {self.natural_frequency}")
        if not (math.isfinite(self.damping_ratio) and self.damping_ratio >= 0):
            raise ConfigError("damping_ratio", f"must be finite and >= 0, got "
                              f"{self.damping_ratio}")
        if not (math.isfinite(self.calibration) and self.calibration > 0):
            raise ConfigError("calibration", f"must be finite and > 0, got {self.calibration}")
        # δ* / f1(α) is constant for the model: the planner asks once per node
        object.__setattr__(self, "_scale",
                           damping_factor(self.damping_ratio) * self.dynamics_factor)

    @property
    def dynamics_factor(self) -> float:
        """f2 = c·(T + 1/ω_min) (s)."""
        return self.calibration * (self.servo_time_constant + 1.0 / self.natural_frequency)

    def relative_error(self, angle: float) -> float:
        """δ* = δ_max / V_node at deflection ``angle`` (rad) (s)."""
        return angle_factor(angle) * self._scale

    def max_node_speed(self, angle: float, tolerance: float) -> float:
        """V_node_accuracy = δ_allowed / δ* (m/s); ``inf`` for a straight-through node."""
        a = abs(angle)
        rel = (math.sin(a) if a < 0.5 * math.pi else 1.0) * self._scale
        return tolerance / rel if rel > 0.0 else math.inf

    @classmethod
    def from_machine(cls, cfg: MachineConfig, *, servo_time_constant: float | None = None,
                     calibration: float = _DEFAULT_CALIBRATION) -> SeedCornerModel:
        """The model for a machine configuration (see `from_axes`).

        ``servo_time_constant`` defaults to the position-loop time constant 1/K_v with
        K_v = kp / (V·s/m of the drive) when ``controller.regulator.kp`` is set, else seed
        001's 0.01 s.
        """
        if servo_time_constant is None:
            kp = cfg.controller.regulator.kp
            servo_time_constant = (max(ax.volts_per_speed for ax in cfg.axes.values()) / kp
                                   if kp else 0.01)
        return cls.from_axes(cfg.axes, servo_time_constant=servo_time_constant,
                             calibration=calibration)

    @classmethod
    def from_axes(cls, axes: Mapping[str, AxisConfig], *, servo_time_constant: float,
                  calibration: float = _DEFAULT_CALIBRATION) -> SeedCornerModel:
        """The model for two axes and a known servo time constant T (s).

        ω of each axis is √(k/m) of its table mass on the series stiffness of the
        transmission (the motor held by its speed loop); the lower axis of the cross table
        (x) carries the upper carriage (y), so its mass is the sum of both. ξ is the
        transmission damping ratio of the axis with the lower ω.
        """
        masses = moving_masses(axes)
        omegas = {ax: math.sqrt(axes[ax].transmission.axial_stiffness / masses[ax])
                  for ax in masses}
        low = min(omegas, key=omegas.__getitem__)
        return cls(servo_time_constant=servo_time_constant, natural_frequency=omegas[low],
                   damping_ratio=axes[low].transmission.damping_ratio,
                   calibration=calibration)


@dataclass(frozen=True)
class NoCornerLimit:
    """A corner model that never limits the node speed (for comparisons)."""

    def max_node_speed(self, angle: float, tolerance: float) -> float:
        """Always ``inf`` (m/s)."""
        return math.inf
