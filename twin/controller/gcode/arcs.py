"""Arc geometry of the reader: the centre of a G2/G3 from I/J or from R, and its sweep.

All inputs and outputs are SI (m, rad). Every arc that leaves the reader is an exact circle
through its start and end point, so nothing downstream has to cope with a spiral.

The tolerance (``ArcTolerance``), stated once
-------------------------------------------
CAM systems round coordinates, so the end point of an I/J arc is seldom exactly on the circle
around the programmed centre. As in grbl and LinuxCNC an arc is refused when the path would
stray from that circle by more than

    allowed(r) = min(maximum, max(absolute, relative · r))
               = min(0.5 mm, max(0.002 mm, 0.1 % of r))     (defaults)

with r the larger of the start and end radius. An accepted arc's centre is then moved onto
the perpendicular bisector of start and end (the nearest such point, "centre-point
correction" of industrial controls), and the deviation checked is that of the corrected arc
from the programmed circle over its whole sweep, not only at the end point: a nearly closed
arc with a short chord amplifies a small end error into a large centre shift, and that is
refused rather than run.

An R arc whose end point is farther than 2·|R| from the start by no more than ``allowed(|R|)``
becomes a half circle; farther is an error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from twin.errors import ConfigError
from twin.units import MM

__all__ = [
    "ArcError",
    "ArcTolerance",
    "arc_sweep",
    "center_from_offset",
    "center_from_radius",
]

_TAU = 2.0 * math.pi

Point = tuple[float, float]


class ArcError(ValueError):
    """An arc that cannot be built; the reader turns it into a ``GCodeError`` with its place.

    Attributes
    ----------
    code : str
        Machine-readable code (``GCodeError.code``).
    message : str
        What is wrong.
    """

    def __init__(self, code: str, message: str):
        self.code = code
        self.message = message
        super().__init__(message)


@dataclass(frozen=True, slots=True)
class ArcTolerance:
    """How far an arc may stray from its programmed circle.

    Attributes
    ----------
    absolute : float
        Always-accepted deviation (m). Default 0.002 mm.
    relative : float
        Accepted deviation as a fraction of the radius (1). Default 0.001 (0.1 %).
    maximum : float
        Never-accepted deviation above this (m), whatever the radius. Default 0.5 mm.
    """

    absolute: float = 0.002 * MM
    relative: float = 1e-3
    maximum: float = 0.5 * MM

    def __post_init__(self) -> None:
        for name in ("absolute", "relative", "maximum"):
            value = getattr(self, name)
            if not (isinstance(value, float | int) and math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"arc_tolerance.{name}", f"must be finite and >= 0, "
                                                           f"got {value!r}")
        if self.maximum < self.absolute:
            raise ConfigError("arc_tolerance.maximum", f"must be >= absolute "
                                                       f"({self.absolute!r}), got {self.maximum!r}")

    def allowed(self, radius: float) -> float:
        """Accepted deviation for an arc of ``radius`` (m)."""
        return min(self.maximum, max(self.absolute, self.relative * radius))

    def describe(self, radius: float) -> str:
        """The rule and its value at ``radius``, for error messages."""
        return (f"allowed {self.allowed(radius) / MM:.4g} mm here: {self.absolute / MM:g} mm "
                f"or {self.relative * 100:g} % of the radius, at most {self.maximum / MM:g} mm")


def arc_sweep(start: Point, end: Point, center: Point, *, ccw: bool, turns: int = 0) -> float:
    """Signed angle swept from ``start`` to ``end`` around ``center`` (rad).

    Counter-clockwise arcs sweep (0, 2π] plus ``turns`` full turns, clockwise arcs the
    negative; ``start == end`` is a full circle.
    """
    if start == end:
        angle = _TAU
    else:
        a0 = math.atan2(start[1] - center[1], start[0] - center[0])
        a1 = math.atan2(end[1] - center[1], end[0] - center[0])
        angle = ((a1 - a0) if ccw else (a0 - a1)) % _TAU
    angle += turns * _TAU
    return angle if ccw else -angle


def _within(direction: float, a0: float, sweep: float) -> bool:
    """Whether the polar angle ``direction`` lies on an arc from ``a0`` sweeping ``sweep``."""
    if abs(sweep) >= _TAU:
        return True
    offset = (direction - a0) % _TAU if sweep > 0.0 else (a0 - direction) % _TAU
    return offset <= abs(sweep)


def center_from_offset(start: Point, end: Point, center: Point, *, ccw: bool, turns: int,
                       tolerance: ArcTolerance) -> Point:
    """Centre of an I/J arc, corrected onto the bisector of start and end (m).

    Parameters
    ----------
    start, end : tuple of float
        Arc start and end (m).
    center : tuple of float
        Programmed centre, start + (I, J) (m).
    ccw : bool
        G3 if True, G2 if False.
    turns : int
        Extra full turns (>= 0).
    tolerance : ArcTolerance
        How far the arc may stray from the programmed circle.

    Returns
    -------
    tuple of float
        The centre of the circle actually run (m); ``center`` itself for a full circle.

    Raises
    ------
    ArcError
        ``arc-zero-radius`` when the centre is the start point, ``arc-end-off-circle`` when
        the arc strays from the programmed circle by more than ``tolerance`` allows.
    """
    (sx, sy), (ex, ey), (cx, cy) = start, end, center
    r_start = math.hypot(sx - cx, sy - cy)
    if r_start == 0.0:
        raise ArcError("arc-zero-radius", "arc centre is the start point (I and J are zero)")
    r_end = math.hypot(ex - cx, ey - cy)
    rule = tolerance.describe(max(r_start, r_end))
    allowed = tolerance.allowed(max(r_start, r_end))
    end_error = abs(r_end - r_start)
    if end_error > allowed:
        raise ArcError("arc-end-off-circle",
                       f"arc end point is {end_error / MM:.4g} mm off the circle around the "
                       f"centre (radius {r_start / MM:.6g} mm at the start, "
                       f"{r_end / MM:.6g} mm at the end; {rule})")
    if start == end:
        return center
    chord = math.hypot(ex - sx, ey - sy)
    ux, uy = (ex - sx) / chord, (ey - sy) / chord
    shift = (cx - 0.5 * (sx + ex)) * ux + (cy - 0.5 * (sy + ey)) * uy
    fixed = (cx - shift * ux, cy - shift * uy)
    if shift == 0.0:
        return fixed
    # The corrected circle's points farthest from and nearest to the programmed centre lie
    # along the chord direction; check them where the arc actually passes.
    radius = math.hypot(sx - fixed[0], sy - fixed[1])
    sweep = arc_sweep(start, end, fixed, ccw=ccw, turns=turns)
    a0 = math.atan2(sy - fixed[1], sx - fixed[0])
    low, high = min(r_start, r_end), max(r_start, r_end)
    worst = end_error
    for sign in (1.0, -1.0):
        if _within(math.atan2(sign * uy, sign * ux), a0, sweep):
            distance = abs(radius - sign * shift)
            worst = max(worst, low - distance, distance - high)
    if worst > allowed:
        raise ArcError("arc-end-off-circle",
                       f"arc end point does not fit the centre: an arc through both end "
                       f"points strays {worst / MM:.4g} mm from the programmed circle "
                       f"({rule})")
    return fixed


def center_from_radius(start: Point, end: Point, radius: float, *, ccw: bool,
                       tolerance: ArcTolerance) -> Point:
    """Centre of an R arc (m): R > 0 the arc of at most 180°, R < 0 the one of more.

    Parameters
    ----------
    start, end : tuple of float
        Arc start and end (m).
    radius : float
        Programmed R (m), signed.
    ccw : bool
        G3 if True, G2 if False.
    tolerance : ArcTolerance
        How much farther apart than 2·|R| start and end may be (then: a half circle).

    Returns
    -------
    tuple of float
        The centre (m), exactly on the bisector of start and end.

    Raises
    ------
    ArcError
        ``arc-zero-radius`` for R = 0, ``arc-full-circle-r`` when start and end coincide (a
        full circle has no unique centre: program it with I/J), ``arc-radius-too-small``
        when the end point is farther than 2·|R| from the start beyond the tolerance.
    """
    if radius == 0.0:
        raise ArcError("arc-zero-radius", "arc radius R is zero")
    if start == end:
        raise ArcError("arc-full-circle-r", "an R arc cannot be a full circle (its end point "
                                            "is its start point); program the centre with I/J")
    (sx, sy), (ex, ey) = start, end
    r = abs(radius)
    half = 0.5 * math.hypot(ex - sx, ey - sy)
    if half > r:
        if half - r > tolerance.allowed(r):
            raise ArcError("arc-radius-too-small",
                           f"arc radius |R| = {r / MM:.6g} mm is too small: the end point is "
                           f"{2.0 * half / MM:.6g} mm from the start "
                           f"({tolerance.describe(r)})")
        height = 0.0
    else:
        height = math.sqrt((r - half) * (r + half))
    ux, uy = (ex - sx) / (2.0 * half), (ey - sy) / (2.0 * half)
    # Short arc: the centre lies left of start→end for G3, right for G2; R < 0 swaps.
    side = (1.0 if ccw else -1.0) * (1.0 if radius > 0.0 else -1.0)
    return (0.5 * (sx + ex) - side * height * uy, 0.5 * (sy + ey) + side * height * ux)
