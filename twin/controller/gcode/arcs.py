"""Arc geometry of the reader: the centre of a G2/G3 from I/J or from R, and its sweep.

All inputs and outputs are SI (m, rad). Every arc that leaves the reader is an exact circle
through its start and end point, so nothing downstream has to cope with a spiral.

The tolerance (``ArcTolerance``), stated once: LinuxCNC's
-------------------------------------------------------
CAM systems round coordinates (3 decimals in mm, 4 in inch), so the end point of an I/J arc
is seldom exactly on the circle around the programmed centre. As LinuxCNC 2.9 does
(``arc_data_ijk``), an arc is refused when its end radius differs from its start radius by

    |r1 - r0| > allowed(r) = min(maximum, max(absolute, relative · r))
                           = min(2.83 mm, max(0.0283 mm, 0.1 % of r))   (G21)
                           = min(0.283 in, max(0.00283 in, 0.1 % of r)) (G20)

with r the larger radius: no arc LinuxCNC runs is refused, and no arc it refuses is run.

What is run instead of the programmed circle: the circle through start and end whose centre
is the point of their bisector nearest to the programmed one ("centre-point correction"),
when that circle strays from the programmed one by no more than allowed(r) over the whole
sweep. Otherwise (a nearly closed arc with a short chord, where the correction would move
the centre far) LinuxCNC's own spiral is run, cut into exact circular pieces of at most 90°
(``spiral_pieces``), within 1.71·|r1 - r0|/n of that spiral. Either way the path stays
within allowed(r) + 1.71·allowed(r)/2 of the programmed circle.

An R arc whose end point is farther than 2·|R| from the start by no more than ``allowed(|R|)``
becomes a half circle; farther is an error.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from twin.errors import ConfigError
from twin.units import INCH, MM

__all__ = [
    "ArcError",
    "ArcTolerance",
    "arc_sweep",
    "center_from_offset",
    "center_from_radius",
    "spiral_pieces",
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
        Always-accepted deviation (m). Default LinuxCNC's 0.02·√2 mm.
    relative : float
        Accepted deviation as a fraction of the radius (1). Default 0.001 (0.1 %).
    maximum : float
        Never-accepted deviation above this (m), whatever the radius. Default 100 times
        ``absolute``.

    ``ArcTolerance.linuxcnc("inch")`` is LinuxCNC's rule in inch programs (0.002·√2 in).
    """

    absolute: float = 0.02 * math.sqrt(2.0) * MM
    relative: float = 1e-3
    maximum: float = 2.0 * math.sqrt(2.0) * MM

    @classmethod
    def linuxcnc(cls, units: str) -> ArcTolerance:
        """LinuxCNC's tolerance in ``"mm"`` or ``"inch"`` programs."""
        if units == "mm":
            return cls()
        absolute = 0.002 * math.sqrt(2.0) * INCH
        return cls(absolute=absolute, maximum=100.0 * absolute)

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
                       tolerance: ArcTolerance) -> list[tuple[Point, Point, Point]]:
    """The exact arcs that run an I/J arc: one corrected circle, or a spiral's pieces (m).

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
        How far the end point may be off the programmed circle.

    Returns
    -------
    list of (start, end, centre)
        One piece, the circle through start and end whose centre is the nearest to the
        programmed one, when that circle stays within ``tolerance`` of the programmed
        circle; otherwise ``spiral_pieces``. A full circle is one piece around ``center``.

    Raises
    ------
    ArcError
        ``arc-zero-radius`` when the centre is the start point, ``arc-end-off-circle`` when
        the end point is off the programmed circle by more than ``tolerance`` allows.
    """
    (sx, sy), (ex, ey), (cx, cy) = start, end, center
    r_start = math.hypot(sx - cx, sy - cy)
    if r_start == 0.0:
        raise ArcError("arc-zero-radius", "arc centre is the start point (I and J are zero)")
    r_end = math.hypot(ex - cx, ey - cy)
    if r_end == 0.0:
        raise ArcError("arc-zero-radius", "arc centre is the end point")
    rule = tolerance.describe(max(r_start, r_end))
    allowed = tolerance.allowed(max(r_start, r_end))
    end_error = abs(r_end - r_start)
    if end_error > allowed:
        raise ArcError("arc-end-off-circle",
                       f"arc end point is {end_error / MM:.4g} mm off the circle around the "
                       f"centre (radius {r_start / MM:.6g} mm at the start, "
                       f"{r_end / MM:.6g} mm at the end; {rule})")
    if start == end:
        return [(start, end, center)]
    fixed, worst = _corrected(start, end, center, ccw=ccw, turns=turns)
    if worst <= allowed:
        return [(start, end, fixed)]
    return spiral_pieces(start, end, center, ccw=ccw, turns=turns)


def _corrected(start: Point, end: Point, center: Point, *, ccw: bool,
               turns: int) -> tuple[Point, float]:
    """The centre on the bisector of start and end nearest to ``center``, and how far the
    arc around it strays from the circle around ``center`` through start and end (m)."""
    (sx, sy), (ex, ey), (cx, cy) = start, end, center
    r_start = math.hypot(sx - cx, sy - cy)
    r_end = math.hypot(ex - cx, ey - cy)
    chord = math.hypot(ex - sx, ey - sy)
    ux, uy = (ex - sx) / chord, (ey - sy) / chord
    shift = (cx - 0.5 * (sx + ex)) * ux + (cy - 0.5 * (sy + ey)) * uy
    fixed = (cx - shift * ux, cy - shift * uy)
    worst = abs(r_end - r_start)
    if shift == 0.0:
        return fixed, worst
    # The corrected circle's points farthest from and nearest to the programmed centre lie
    # along the chord direction; check them where the arc actually passes.
    radius = math.hypot(sx - fixed[0], sy - fixed[1])
    sweep = arc_sweep(start, end, fixed, ccw=ccw, turns=turns)
    a0 = math.atan2(sy - fixed[1], sx - fixed[0])
    low, high = min(r_start, r_end), max(r_start, r_end)
    for sign in (1.0, -1.0):
        if _within(math.atan2(sign * uy, sign * ux), a0, sweep):
            distance = abs(radius - sign * shift)
            worst = max(worst, low - distance, distance - high)
    return fixed, worst


SPIRAL_PIECE = 0.5 * math.pi
"""Largest sweep of one piece of a spiral (rad)."""


def spiral_pieces(start: Point, end: Point, center: Point, *, ccw: bool,
                  turns: int) -> list[tuple[Point, Point, Point]]:
    """LinuxCNC's spiral for an arc whose end is off its circle, as exact circular pieces.

    LinuxCNC runs such an arc as a spiral around the programmed centre whose radius goes
    linearly with the angle from the start radius r0 to the end radius r1. Here the spiral
    is cut into n equal pieces of at most ``SPIRAL_PIECE`` (90°), each an exact circle
    through two points of the spiral with its centre on their bisector nearest to the
    programmed centre. A piece's radii differ by δ = |r1 - r0|/n, its centre moves by about
    δ/(2·sin(θ/2)) ≤ 0.71·δ, so each piece stays within 1.71·|r1 - r0|/n of the spiral, and
    the path within |r1 - r0|·(1 + 1.71/n) of the programmed circle (the tests check the
    bound by sampling)."""
    (sx, sy), (ex, ey), (cx, cy) = start, end, center
    r0 = math.hypot(sx - cx, sy - cy)
    r1 = math.hypot(ex - cx, ey - cy)
    a0 = math.atan2(sy - cy, sx - cx)
    sweep = arc_sweep(start, end, center, ccw=ccw, turns=turns)
    n = max(2, math.ceil(abs(sweep) / SPIRAL_PIECE))
    points = [start]
    for k in range(1, n):
        f = k / n
        angle = a0 + f * sweep
        radius = r0 + f * (r1 - r0)
        points.append((cx + radius * math.cos(angle), cy + radius * math.sin(angle)))
    points.append(end)
    return [(p, q, _corrected(p, q, center, ccw=ccw, turns=0)[0])
            for p, q in itertools.pairwise(points)]


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
