"""Unit conversions at the edges. Inside xy-twin everything is SI, float64.

Convert exactly once where a value enters or leaves: the G-code reader (mm, inch, mm/min),
the encoder (counts), the DAC (volts, codes) and the reports (µm, mm/min).
"""

from __future__ import annotations

import math

__all__ = [
    "INCH",
    "MM",
    "MM_PER_MIN",
    "RPM",
    "UM",
    "mm",
    "mm_per_min",
    "rpm",
    "to_mm",
    "to_mm_per_min",
    "to_um",
]

MM = 1e-3
"""One millimetre (m)."""
UM = 1e-6
"""One micrometre (m)."""
INCH = 25.4e-3
"""One inch (m)."""
MM_PER_MIN = 1e-3 / 60.0
"""One mm/min (m/s)."""
RPM = 2.0 * math.pi / 60.0
"""One revolution per minute (rad/s)."""


def mm(value: float) -> float:
    """Millimetres to metres."""
    return value * MM


def mm_per_min(value: float) -> float:
    """mm/min to m/s."""
    return value * MM_PER_MIN


def rpm(value: float) -> float:
    """rev/min to rad/s."""
    return value * RPM


def to_mm(value: float) -> float:
    """Metres to millimetres."""
    return value / MM


def to_um(value: float) -> float:
    """Metres to micrometres."""
    return value / UM


def to_mm_per_min(value: float) -> float:
    """m/s to mm/min."""
    return value / MM_PER_MIN
