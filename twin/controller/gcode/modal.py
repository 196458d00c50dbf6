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
    ("G", 5): Code("motion", "cubic"),             # G5  cubic spline (Bézier) at F
    ("G", 5.1): Code("motion", "quadratic"),       # G5.1 quadratic spline at F
    ("G", 80): Code("motion", None),               # G80 cancel motion mode (power-on)
    # canned cycles: their moves between the holes (Z ignored, or the tool: see the reader)
    **{("G", g): Code("motion", f"cycle_g{g}") for g in (73, 81, 82, 83, 84, 85, 86, 87,
                                                          88, 89)},
    # -- G group 0, non-modal -------------------------------------------------------------
    ("G", 4): Code("non_modal", "dwell"),          # G4  dwell P seconds
    ("G", 10): Code("non_modal", "set_offsets"),   # G10 L2/L20 P: work offsets
    ("G", 28): Code("non_modal", "home_g28"),      # G28 rapid home (via given axes)
    ("G", 30): Code("non_modal", "home_g30"),      # G30 rapid to the second home
    ("G", 28.1): Code("non_modal", "set_g28"),     # G28.1 store the G28 position
    ("G", 30.1): Code("non_modal", "set_g30"),     # G30.1 store the G30 position
    ("G", 53): Code("non_modal", "machine"),       # G53 move in machine coordinates
    ("G", 92): Code("non_modal", "g92"),           # G92 offset so the point is here
    ("G", 92.1): Code("non_modal", "g92_reset"),   # G92.1 cancel G92, zero its parameters
    ("G", 92.2): Code("non_modal", "g92_off"),     # G92.2 cancel G92, keep its parameters
    ("G", 92.3): Code("non_modal", "g92_restore"),  # G92.3 G92 from its parameters
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
    # -- G group 4, arc centre distance mode -----------------------------------------------
    ("G", 90.1): Code("arc_distance", "absolute"),     # G90.1 I/J absolute
    ("G", 91.1): Code("arc_distance", "incremental"),  # G91.1 I/J from the start (power-on)
    # -- G group 7, cutter compensation: only off ------------------------------------------
    ("G", 40): Code("cutter_comp", "off"),         # G40 cutter compensation off
    ("G", 41): Code("cutter_comp", "left", "cutter radius compensation (G41) is not "
                    "supported: program the tool centre path"),
    ("G", 42): Code("cutter_comp", "right", "cutter radius compensation (G42) is not "
                    "supported: program the tool centre path"),
    ("G", 41.1): Code("cutter_comp", "left", "cutter radius compensation (G41.1) is not "
                      "supported: program the tool centre path"),
    ("G", 42.1): Code("cutter_comp", "right", "cutter radius compensation (G42.1) is not "
                      "supported: program the tool centre path"),
    # -- G group 8, tool length offset: along Z only, so no effect on X and Y ------------
    ("G", 43): Code("tool_length", "on"),          # G43 [H]: accepted, a Z offset
    ("G", 43.1): Code("tool_length", "on"),        # G43.1: accepted, a Z offset
    ("G", 49): Code("tool_length", "off"),         # G49 tool length offset off
    # -- G group 12, coordinate system ----------------------------------------------------
    ("G", 54): Code("coordinate_system", 1),       # G54 work offsets 1 (power-on)
    ("G", 55): Code("coordinate_system", 2),
    ("G", 56): Code("coordinate_system", 3),
    ("G", 57): Code("coordinate_system", 4),
    ("G", 58): Code("coordinate_system", 5),
    ("G", 59): Code("coordinate_system", 6),
    ("G", 59.1): Code("coordinate_system", 7),
    ("G", 59.2): Code("coordinate_system", 8),
    ("G", 59.3): Code("coordinate_system", 9),
    # -- G group 13, path control ---------------------------------------------------------
    ("G", 61): Code("path", "exact_path"),         # G61 exact path: corners not rounded
    ("G", 61.1): Code("path", "exact_stop"),       # G61.1 exact stop at every move end
    ("G", 64): Code("path", "blend"),              # G64 [P Q] blend (power-on)
    # -- G group 14, spindle speed mode: RPM only ------------------------------------------
    ("G", 97): Code("spindle_mode", "rpm"),        # G97 RPM mode (power-on)
    # -- G group 10, canned cycle return mode: accepted, no cycles run --------------------
    ("G", 98): Code("return_mode", "initial"),
    ("G", 99): Code("return_mode", "r_plane"),
    # -- M group 4, stopping --------------------------------------------------------------
    ("M", 2): Code("stopping", "M2"),              # M2  program end
    ("M", 30): Code("stopping", "M30"),            # M30 program end (and rewind)
    ("M", 0): Code("pause", "M0"),                 # M0  program pause (the twin runs on)
    ("M", 1): Code("pause", "M1"),                 # M1  optional pause
    ("M", 60): Code("pause", "M60"),               # M60 pallet change pause
    # -- M group 9, overrides: accepted, the twin has no override knobs ------------------
    ("M", 48): Code("overrides", "on"),
    ("M", 49): Code("overrides", "off"),
    # -- M groups the twin refuses with the feature they need ---------------------------
    ("M", 70): Code("modal_state", "save", "modal-state save (M70) is not supported"),
    ("M", 71): Code("modal_state", "invalidate", "modal-state save (M71) is not supported"),
    ("M", 72): Code("modal_state", "restore", "modal-state restore (M72) is not supported"),
    ("M", 73): Code("modal_state", "autorestore", "modal-state save (M73) is not "
                    "supported"),
    ("M", 66): Code("io", "wait", "waiting on an input (M66) is not supported"),
    ("M", 61): Code("tool_change", "set"),         # M61 Q: the tool in the spindle is Q
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

_REFUSED_G = {
    (76,): "the lathe threading cycle (G76) is not supported on an XY table",
    **{(g,): "probing (G38.x) is not supported: the twin has no probe input"
       for g in (38.2, 38.3, 38.4, 38.5)},
    (33,): "spindle-synchronised motion (G33) is not supported: no spindle encoder",
    **{(g,): "lathe roughing and finishing cycles (G70–G72) are not supported on an XY "
             "table" for g in (70, 71, 71.1, 71.2, 72, 72.1, 72.2)},
    (33.1,): "rigid tapping (G33.1) is not supported: no spindle encoder",
    (7,): "lathe diameter mode (G7) is not supported on an XY table",
    (8,): "lathe radius mode (G8) is not supported on an XY table",
    (96,): "constant surface speed (G96) is not supported: no spindle control",
    (5.2,): "NURBS (G5.2) are not supported: program G5 or G5.1 splines",
    (2.5,): "arcs in another plane are not supported",
    (17.1,): "the UV planes (G17.1–G19.1) are not supported",
    (18.1,): "the UV planes (G17.1–G19.1) are not supported",
    (19.1,): "the UV planes (G17.1–G19.1) are not supported",
}
for (_g,), _why in _REFUSED_G.items():
    CODES[("G", _g)] = Code("refused", None, _why)

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
    "spindle_mode": "spindle speed mode",
    "arc_distance": "arc distance mode",
    "path": "path control",
    "return_mode": "canned cycle return mode",
    "pause": "pause",
    "overrides": "overrides",
    "modal_state": "modal state",
    "io": "input/output",
    "refused": "unsupported",
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
    arc_distance : str
        ``"incremental"`` (G91.1: I/J from the start, power-on) or ``"absolute"`` (G90.1).
    coordinate_system : int
        Work offsets in force: 1 (G54, power-on) to 9 (G59.3).
    path : str
        ``"blend"`` (G64, power-on), ``"exact_path"`` (G61), ``"exact_stop"`` (G61.1).
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
    arc_distance: str = "incremental"
    coordinate_system: int = 1
    path: str = "blend"

    @property
    def unit(self) -> float:
        """One program length unit (m): 1 mm or 1 inch."""
        return INCH if self.units == "inch" else MM
