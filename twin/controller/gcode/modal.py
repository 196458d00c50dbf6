"""The G and M codes this machine reads, their modal groups, and the modal state.

One table, in the manner of grbl's ``gcode.h``: each known code names its modal group and the
value the group takes. At most one word of a group may appear in a block. A code with a
refusal text is known (so the error is precise) but not run on this machine.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from twin.units import INCH, MM

__all__ = ["CODES", "GROUP_NAMES", "Code", "ModalState", "code_name"]


class Code(NamedTuple):
    """One row of the table."""

    group: str
    """Modal group key (``GROUP_NAMES``)."""
    value: str | None
    """What the group becomes when the word appears."""
    refusal: str | None = None
    """Why this machine refuses the code; None if it runs it."""


# Key: (letter, number). A word's value finds its row directly: G01 and G1.0 are ("G", 1.0),
# which equals and hashes as ("G", 1).
CODES: dict[tuple[str, float], Code] = {
    # -- G group 1, motion ----------------------------------------------------------------
    ("G", 0): Code("motion", "rapid"),             # G0  rapid positioning
    ("G", 1): Code("motion", "line"),              # G1  straight line at F
    ("G", 2): Code("motion", "arc_cw"),            # G2  clockwise arc at F
    ("G", 3): Code("motion", "arc_ccw"),           # G3  counter-clockwise arc at F
    ("G", 80): Code("motion", None),               # G80 cancel motion mode (power-on)
    # -- G group 0, non-modal -------------------------------------------------------------
    ("G", 4): Code("non_modal", "dwell"),          # G4  dwell P seconds
    # -- G group 2, plane -----------------------------------------------------------------
    ("G", 17): Code("plane", "xy"),                # G17 XY plane (power-on)
    ("G", 18): Code("plane", "xz"),                # G18 XZ: accepted, no motion in it
    ("G", 19): Code("plane", "yz"),                # G19 YZ: accepted, no motion in it
    # -- G group 3, distance mode ---------------------------------------------------------
    ("G", 90): Code("distance", "absolute"),       # G90 absolute (power-on)
    ("G", 91): Code("distance", "incremental"),    # G91 incremental
    # -- G group 5, feed rate mode --------------------------------------------------------
    ("G", 93): Code("feed_mode", "inverse_time",   # G93 inverse time: refused
                    "inverse-time feed (G93) is not supported; program F in units/min (G94)"),
    ("G", 94): Code("feed_mode", "per_minute"),    # G94 units per minute (power-on)
    ("G", 95): Code("feed_mode", "per_revolution",  # G95 units per revolution: refused
                    "feed per revolution (G95) is not supported: this machine has no "
                    "spindle feedback; program F in units/min (G94)"),
    # -- G group 6, units -----------------------------------------------------------------
    ("G", 20): Code("units", "inch"),              # G20 inch
    ("G", 21): Code("units", "mm"),                # G21 millimetre (power-on)
    # -- G groups 7, 8, 12: states this machine is always in, accepted for CAM headers ----
    ("G", 40): Code("cutter_comp", "off"),         # G40 cutter compensation off (no other)
    ("G", 49): Code("tool_length", "off"),         # G49 tool length offset off (no Z axis)
    ("G", 54): Code("coordinate_system", "G54"),   # G54 = machine coordinates (no offsets)
    # -- M group 4, stopping --------------------------------------------------------------
    ("M", 2): Code("stopping", "M2"),              # M2  program end
    ("M", 30): Code("stopping", "M30"),            # M30 program end (and rewind)
    # -- M group 6, tool change -----------------------------------------------------------
    ("M", 6): Code("tool_change", "change"),       # M6  change to the selected tool (T)
    # -- M group 7, spindle ---------------------------------------------------------------
    ("M", 3): Code("spindle", "cw"),               # M3  spindle clockwise
    ("M", 4): Code("spindle", "ccw"),              # M4  spindle counter-clockwise
    ("M", 5): Code("spindle", "stop"),             # M5  spindle stop (power-on)
    # -- M group 8, coolant ---------------------------------------------------------------
    ("M", 7): Code("coolant", "mist"),             # M7  mist coolant
    ("M", 8): Code("coolant", "flood"),            # M8  flood coolant
    ("M", 9): Code("coolant", "off"),              # M9  coolant off (power-on)
}

GROUP_NAMES = {
    "motion": "motion",
    "non_modal": "non-modal",
    "plane": "plane",
    "distance": "distance mode",
    "feed_mode": "feed rate mode",
    "units": "units",
    "cutter_comp": "cutter compensation",
    "tool_length": "tool length offset",
    "coordinate_system": "coordinate system",
    "stopping": "program end",
    "tool_change": "tool change",
    "spindle": "spindle",
    "coolant": "coolant",
}
"""Group key → name used in messages (``two motion words in one block (G0, G1)``)."""


def code_name(letter: str, value: float) -> str:
    """How a code is written in messages: ``G1``, ``G91.1``, ``M30``."""
    return f"{letter}{value:.12g}"


@dataclass(frozen=True, slots=True)
class ModalState:
    """What stays in force from block to block. Defaults are the power-on state.

    Attributes
    ----------
    motion : str or None
        ``"rapid"``, ``"line"``, ``"arc_cw"``, ``"arc_ccw"``; None (G80, power-on): axis words
        without a motion word are an error until one is programmed.
    plane : str
        ``"xy"`` (G17), ``"xz"`` (G18) or ``"yz"`` (G19).
    distance : str
        ``"absolute"`` (G90) or ``"incremental"`` (G91).
    units : str
        ``"mm"`` (G21) or ``"inch"`` (G20).
    feed_mode : str
        ``"per_minute"`` (G94), the only one this machine runs.
    feed : float or None
        Programmed feed (m/s), None until an F word. Stored in SI, so a later G20/G21 keeps
        the physical speed.
    spindle : str
        ``"stop"``, ``"cw"``, ``"ccw"``.
    spindle_speed : float
        Last S word (rad/s).
    coolant : str
        ``"off"``, ``"mist"``, ``"flood"``.
    tool : int or None
        Last T word (selected tool), None until one.
    """

    motion: str | None = None
    plane: str = "xy"
    distance: str = "absolute"
    units: str = "mm"
    feed_mode: str = "per_minute"
    feed: float | None = None
    spindle: str = "stop"
    spindle_speed: float = 0.0
    coolant: str = "off"
    tool: int | None = None

    @property
    def unit(self) -> float:
        """One program length unit (m): 1 mm or 1 inch."""
        return INCH if self.units == "inch" else MM
