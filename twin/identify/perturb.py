"""Machines ``twin identify`` has not seen: BASE with its physical parameters drawn at
random within the ranges a real machine of the same design may differ by.

Per axis, independently: tacho gain ×(0.8 … 1.2), rotor inertia ×(0.7 … 1.5), Coulomb
friction (rotor and slide together) ×(0.5 … 3), viscous friction ×(0.5 … 3), break-away
1 … 1.5 × Coulomb, armature R and L ×(0.7 … 1.3), lost motion 0 … 20 µm. The I/O, the
limits and everything the signals cannot see stay BASE's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from twin.config import AXES, MachineConfig

__all__ = ["RANGES", "perturbed_machine"]

RANGES = {"tacho_gain": (0.8, 1.2), "inertia": (0.7, 1.5), "coulomb": (0.5, 3.0),
          "viscous": (0.5, 3.0), "breakaway": (1.0, 1.5), "resistance": (0.7, 1.3),
          "inductance": (0.7, 1.3), "backlash": (0.0, 20e-6)}
"""Factor (or, for the lost motion, value in m; for the break-away, ratio to Coulomb) ranges."""


def perturbed_machine(base: MachineConfig, rng: np.random.Generator, *,
                      name: str = "unseen") -> MachineConfig:
    """BASE with every ``RANGES`` parameter of each axis drawn uniformly."""
    sets: dict[str, float] = {}
    for a in AXES:
        ax = base.axes[a]
        m = ax.mechanics
        f = {k: float(rng.uniform(*r)) for k, r in RANGES.items()}
        pre = f"axes.{a}"
        rotor_c, slide_c = f["coulomb"] * m.rotor_coulomb, f["coulomb"] * m.slide_coulomb
        sets.update({
            f"{pre}.tacho.gain": f["tacho_gain"] * ax.tacho.gain,
            f"{pre}.mechanics.rotor_inertia": f["inertia"] * m.rotor_inertia,
            f"{pre}.mechanics.rotor_coulomb": rotor_c,
            f"{pre}.mechanics.slide_coulomb": slide_c,
            f"{pre}.mechanics.rotor_viscous": f["viscous"] * m.rotor_viscous,
            f"{pre}.mechanics.slide_viscous": f["viscous"] * m.slide_viscous,
            f"{pre}.mechanics.rotor_breakaway": f["breakaway"] * rotor_c,
            f"{pre}.mechanics.slide_breakaway": f["breakaway"] * slide_c,
            f"{pre}.motor.armature_resistance": f["resistance"]
            * ax.motor.armature_resistance,
            f"{pre}.motor.armature_inductance": f["inductance"]
            * ax.motor.armature_inductance,
            f"{pre}.transmission.backlash": f["backlash"],
        })
    return dataclasses.replace(base.with_overrides(sets), name=name)
