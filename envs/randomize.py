"""Machine randomiser: draws plausible variants of a machine for training tuning policies.

Each parameter of ``RANGES`` is multiplied, per axis and independently, by a factor drawn
log-uniformly from its documented range, so a policy sees machines it was not tuned on.
The ranges are what one machine design spreads over in practice (assumptions; no source
document gives them):

====================================  ===========  ==================================
parameter (per axis)                  factor       why it varies
====================================  ===========  ==================================
``mechanics.carriage_mass``           0.6 … 1.6    workpiece and fixture on the table
``mechanics.rotor_inertia``           0.7 … 1.5    motor and gear variants
``mechanics.slide_coulomb``           0.5 … 2.0    way lubrication, gib adjustment
``mechanics.slide_viscous``           0.5 … 2.0    oil temperature
``mechanics.rotor_coulomb``           0.5 … 2.0    brush and gear wear
``transmission.stiffness`` (all)      0.5 … 2.0    screw length in use, nut preload
``transmission.damping_ratio``        0.5 … 2.0    joint damping
``motor.emf_constant``                0.9 … 1.1    magnet tolerance
``motor.armature_resistance``         0.8 … 1.25   winding temperature
``motor.armature_inductance``         0.8 … 1.25   saturation
``tacho.gain``                        0.95 … 1.05  tachogenerator tolerance
====================================  ===========  ==================================

A draw that the machine schema rejects (e.g. a damping ratio above its bound) is clipped
to the bound rather than redrawn, so a seed always gives one machine; a draw whose fastest
elastic mode the base's physics step does not resolve gets more physics steps per drive
interval (the drive interval, and with it the controller's period, stays).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig, load_machine
from twin.config.schema import ELASTIC_STEP
from twin.errors import ConfigError

__all__ = ["RANGES", "MachineRandomizer"]

RANGES: dict[str, tuple[float, float]] = {
    "mechanics.carriage_mass": (0.6, 1.6),
    "mechanics.rotor_inertia": (0.7, 1.5),
    "mechanics.slide_coulomb": (0.5, 2.0),
    "mechanics.slide_viscous": (0.5, 2.0),
    "mechanics.rotor_coulomb": (0.5, 2.0),
    "transmission.stiffness": (0.5, 2.0),
    "transmission.damping_ratio": (0.5, 2.0),
    "motor.emf_constant": (0.9, 1.1),
    "motor.armature_resistance": (0.8, 1.25),
    "motor.armature_inductance": (0.8, 1.25),
    "tacho.gain": (0.95, 1.05),
}
"""Factor range (low, high) of each per-axis parameter (dotted path under ``axes.<ax>``)."""

_UPPER = {"transmission.damping_ratio": 2.0}  # schema bounds a factor may not cross


def _get(obj: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


@dataclass(frozen=True)
class MachineRandomizer:
    """Draws variants of ``base``.

    Attributes
    ----------
    base : MachineConfig
        The nominal machine.
    ranges : mapping of str to (float, float)
        Factor ranges by per-axis dotted path (default ``RANGES``); each ``0 < low ≤ high``.
    """

    base: MachineConfig
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=lambda: dict(RANGES))

    def __post_init__(self) -> None:
        for key, pair in self.ranges.items():
            try:
                low, high = (float(v) for v in pair)
            except (TypeError, ValueError):
                raise ConfigError(f"ranges.{key}", f"must be (low, high), got {pair!r}") \
                    from None
            if not (math.isfinite(low) and math.isfinite(high) and 0.0 < low <= high):
                raise ConfigError(f"ranges.{key}", f"must satisfy 0 < low <= high, got "
                                  f"{pair!r}")
            _get(self.base.axes[AXES[0]], key)  # AttributeError names an unknown path

    @classmethod
    def of(cls, machine: str | MachineConfig, **options: Any) -> MachineRandomizer:
        """A randomiser around a preset name, TOML path or config."""
        base = machine if isinstance(machine, MachineConfig) else load_machine(machine)
        return cls(base, **options)

    def overrides(self, rng: np.random.Generator) -> dict[str, Any]:
        """Dotted overrides of one draw (``MachineConfig.with_overrides`` form)."""
        out: dict[str, Any] = {}
        for ax in AXES:
            axis = self.base.axes[ax]
            for key, (low, high) in self.ranges.items():
                factor = math.exp(rng.uniform(math.log(low), math.log(high)))
                value = _get(axis, key)
                if isinstance(value, dict):
                    for name, v in value.items():
                        out[f"axes.{ax}.{key}.{name}"] = float(v) * factor
                    continue
                scaled = float(value) * factor
                if key in _UPPER:
                    scaled = min(scaled, _UPPER[key])
                out[f"axes.{ax}.{key}"] = scaled
        return out

    def sample(self, rng: np.random.Generator, *, name: str | None = None) -> MachineConfig:
        """One machine drawn with ``rng``; named ``name`` (default ``<base>~random``)."""
        over = self.overrides(rng)
        sim = self.base.simulation
        # a stiffer draw may have a faster elastic mode than the base's physics step
        # resolves (the screw body between its springs): more steps per drive interval
        fine = self.base.with_overrides({**over, "simulation.timestep": sim.timestep / 16,
                                         "simulation.drive_substeps": sim.drive_substeps * 16})
        fastest = max(a.transmission.fastest_mode(fine.moving_masses()[k],
                                                  a.mechanics.rotor_inertia, a.mechanics.travel)
                      for k, a in fine.axes.items())
        drive_dt = sim.timestep * sim.drive_substeps
        steps = math.ceil(fastest * drive_dt / ELASTIC_STEP)
        if steps > sim.drive_substeps:
            over |= {"simulation.timestep": drive_dt / steps,
                     "simulation.drive_substeps": steps}
        cfg = self.base.with_overrides(over)
        return dataclasses.replace(cfg, name=name or f"{self.base.name}~random")
