"""Machines ``twin identify`` has not seen: BASE with its physical parameters drawn at
random within the ranges a real machine of the same design may differ by.

Per axis, independently (``RANGES``): tacho gain ×(0.8 … 1.2), rotor inertia ×(0.7 … 1.5),
Coulomb friction (rotor and slide together) ×(0.5 … 3), viscous friction ×(0.5 … 3),
break-away 1 … 1.5 × Coulomb, armature R and L ×(0.7 … 1.3), lost motion 0 … 20 µm, DAC
gain error ±1 % and offset ±20 mV. With ``drive`` the drive is also one set by hand at
commissioning (``DRIVE_RANGES``): the speed regulator's gain ×(0.5 … 1.5) and integral time
×(0.5 … 2) of what the symmetric optimum gives for the machine's own inertia; ``"as_built"``
(the issue's KEMEK-era drive) also has analog regulators, a brush drop of 1 … 2 V and no
adaptation to discontinuous conduction; ``"mistuned"`` keeps the digital regulators and
the adaptation. The I/O,
the limits and everything the signals cannot see stay BASE's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from twin.config import AXES, MachineConfig
from twin.drive.design import design

__all__ = ["DRIVES", "DRIVE_RANGES", "RANGES", "perturbed_machine", "true_params"]

RANGES = {"tacho_gain": (0.8, 1.2), "inertia": (0.7, 1.5), "coulomb": (0.5, 3.0),
          "viscous": (0.5, 3.0), "breakaway": (1.0, 1.5), "resistance": (0.7, 1.3),
          "inductance": (0.7, 1.3), "backlash": (0.0, 20e-6), "gain_error": (-0.01, 0.01),
          "offset": (-0.02, 0.02)}
"""Factor (or, for the lost motion, value in m; for the break-away, ratio to Coulomb; for
the DAC's gain error and offset, the value in 1 and V) ranges."""

DRIVE_RANGES = {"speed_kp": (0.5, 1.5), "speed_ti": (0.5, 2.0), "brush_drop": (1.0, 2.0)}
"""A drive mistuned at commissioning: factors of the designed speed gain and integral time,
brush drop (V)."""


DRIVES = (None, "mistuned", "as_built")
"""The kinds of drive ``perturbed_machine`` draws."""


def perturbed_machine(base: MachineConfig, rng: np.random.Generator, *,
                      name: str = "unseen", drive: str | None = None) -> MachineConfig:
    """BASE with every ``RANGES`` parameter of each axis drawn uniformly (and, with
    ``drive``, a hand-set drive: ``DRIVE_RANGES``, see the module docstring)."""
    if drive not in DRIVES:
        raise ValueError(f"drive must be one of {DRIVES}, got {drive!r}")
    sets: dict[str, float | bool | str] = {}
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
            f"{pre}.dac.gain_error": f["gain_error"],
            f"{pre}.dac.offset": f["offset"],
        })
    machine = base.with_overrides(sets)
    if drive:
        masses = machine.moving_masses()
        tuned: dict[str, float | bool | str] = {}
        for a in AXES:
            d = design(machine.axes[a], moving_mass=masses[a])  # its own designed drive
            g = {k: float(rng.uniform(*r)) for k, r in DRIVE_RANGES.items()}
            pre = f"axes.{a}"
            tuned.update({f"{pre}.regulators.speed_kp": g["speed_kp"] * d.speed_kp,
                          f"{pre}.regulators.speed_ti": g["speed_ti"] * d.speed_ti})
            if drive == "as_built":
                tuned.update({f"{pre}.regulators.implementation": "analog",
                              f"{pre}.motor.brush_drop": g["brush_drop"],
                              f"{pre}.converter.dcm_compensation": False})
        machine = machine.with_overrides(tuned)
    return dataclasses.replace(machine, name=name)


def true_params(base: MachineConfig, machine: MachineConfig) -> dict:
    """What a perfect identification of ``machine`` from BASE would report: its
    ``replay.AxisParams`` per axis, the friction as multipliers of BASE's."""
    from twin.identify.replay import base_params

    own = base_params(machine)
    out = {}
    for a in AXES:
        m, b = machine.axes[a].mechanics, base.axes[a].mechanics
        out[a] = own[a].with_(coulomb=m.rotor_coulomb / b.rotor_coulomb,
                              viscous=m.rotor_viscous / b.rotor_viscous)
    return out
