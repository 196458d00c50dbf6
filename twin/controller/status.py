"""What the cyclic controller reports: its status (``ControllerStatus``) and the fields of its
per-tick record (``RECORD_FIELDS``)."""

from __future__ import annotations

from enum import IntEnum

from twin.controller.regulator import TERMS

__all__ = ["INTEGER_FIELDS", "RECORD_FIELDS", "ControllerStatus"]


class ControllerStatus(IntEnum):
    """What the controller is doing; values ≥ ``LIMIT_TRIP`` are latched faults."""

    IDLE = 0
    """Nothing to run: outputs zero, drives disabled."""
    RUNNING = 1
    """Following the program (or a jog)."""
    DWELLING = 2
    """G4: holding position with the loop closed."""
    HOMING = 3
    """Moving toward a home switch, or braking after it closed."""
    SETTLING = 4
    """Motion done; loop closed on the end point until in position (``settle_time`` at
    least, ``settle_timeout`` at most)."""
    FINISHED = 5
    """Done: outputs zero, drives disabled."""
    LIMIT_TRIP = 6
    """An end limit switch closed: outputs zero, disabled."""
    FOLLOWING_ERROR = 7
    """|x_ref − x| exceeded the limit: outputs zero, disabled."""
    INVALID_INPUT = 8
    """A non-finite reference or measurement: outputs zero, disabled."""
    DRIVE_FAULT = 9
    """The drives reported not ready: outputs zero, disabled."""
    PROGRAM_ERROR = 10
    """The program failed while streaming (see ``Controller.error``); stopped at rest."""
    HOMING_FAILED = 11
    """The homing move ended without the home switch closing."""


RECORD_FIELDS = (
    ("t", 1), ("ref_position", 2), ("ref_velocity", 2), ("ref_acceleration", 2),
    ("ref_jerk", 2), ("position", 2), ("following_error", 2), ("dac_volts", 2),
    ("tacho_volts", 2), ("terms", (2, len(TERMS))), ("enable", 1), ("block", 1),
    ("line", 1), ("status", 1))
"""Fields of ``Controller.record``: time (s), references (m, m/s, m/s², m/s³), measured
position (m), following error x_ref − x (m), DAC and tacho volts (V), regulator terms (V,
columns ``regulator.TERMS``: p, i, d, ff, dcu), drive enable, active block index, source line
and ``ControllerStatus`` code."""

INTEGER_FIELDS = ("enable", "block", "line", "status")
"""The fields of ``RECORD_FIELDS`` held as integers."""
