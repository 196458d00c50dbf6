"""The CNC controller stack: G-code, geometry, profiles, planner, interpolators, regulator,
DCU, metrics and the cyclic controller. Hardware independent: it talks to a machine only
through ``MachineIO`` and imports only numpy, scipy and ruckig.
"""

from twin.controller.io import AXES, Inputs, MachineIO, Outputs

__all__ = ["AXES", "Inputs", "MachineIO", "Outputs"]
