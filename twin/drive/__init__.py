"""Discrete models of the axis drives: converter (thyristor bridge or PWM), DC motor,
current and speed loops, tachogenerator. Numerics only (numpy/numba), no MuJoCo.

- :mod:`twin.drive.design`: regulator constants derived by the modulus and symmetric optimum
  (:func:`design` → :class:`DriveDesign`).
- :mod:`twin.drive.drives`: :class:`Drives`, all axes advanced by one compiled call per
  update interval (:mod:`twin.drive.kernel`), exact armature integration between firing
  instants (:mod:`twin.drive.armature`), interval-average torque for the mechanics.
- :mod:`twin.drive.linear`: the linear model from speed reference (V) to table position (m)
  that the controller's DCU derivation uses, its current loop written out as built.
"""

from twin.drive.design import DriveDesign, axis_inertia, design
from twin.drive.drives import Drives
from twin.drive.linear import (
    axis_transfer_function,
    current_transfer_function,
    speed_transfer_function,
    velocity_gain,
)

__all__ = [
    "DriveDesign",
    "Drives",
    "axis_inertia",
    "axis_transfer_function",
    "current_transfer_function",
    "design",
    "speed_transfer_function",
    "velocity_gain",
]
