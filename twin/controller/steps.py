"""Unit-increment (step) interpolators for stepper-drive controllers (seeds 002 and 003).

Every function turns an integer move, in grid steps (motor pulses), into the ordered list of
steps ``(dx, dy)`` that a pulse interpolator would emit. The list ends exactly on the end
point. The evaluation-function ("OF") methods emit strictly unit steps, one axis at a time
(``(±1, 0)`` or ``(0, ±1)``); the DDA emits one tuple per clock that produced a pulse, which
is diagonal (``(±1, ±1)``) when both accumulators overflow in the same clock.

Lines (end point ``(xe, ye)`` relative to the start, any quadrant; ``a = |xe|, b = |ye|``,
signs applied to the output as in the seed)

* classic OF (seed 003): ``F = a·y − b·x`` starts at 0; ``F ≥ 0`` → step X, ``F −= b``;
  else step Y, ``F += a``. Every node satisfies ``−b ≤ F < a``, so its normal distance to
  the line is at most ``max(a, b)/√(a² + b²) < 1`` step.
* extrapolated OF (seed 002): the sign of F is taken half a step ahead in both coordinates,
  ``F(x + ½, y + ½) = F + (a − b)/2`` (kept doubled, in integers). That midpoint lies half
  way between the two candidate nodes, and F is linear, so the rule picks the candidate
  nearer to the line. Moreover every node keeps ``−(a + b)/2 ≤ F < (a + b)/2``: on every
  anti-diagonal ``x + y = k`` (nodes spaced ``a + b`` apart in F) the staircase visits a
  node nearest to the line (of a tie, the one below it). Any monotone unit-step path visits
  one node per anti-diagonal, so no such path has a smaller maximum deviation; the bound is
  ``(a + b)/(2·√(a² + b²)) ≤ √2/2`` step.

Arcs (integer start, end and centre; radius ``R = |start − centre|``, ``F = x² + y² − R²``
relative to the centre, updated incrementally: a step ``s`` on x adds ``2·s·x + 1``)

Within a quadrant the motion is monotone in both axes, one axis moving towards the centre
(inward) and the other away from it. The classic rule steps inward when ``F ≥ 0`` and
outward otherwise, so every node keeps ``|r − R| ≤ 1`` step. The extrapolated rule takes the
sign of F at the midpoint of the two candidates, ``F + sx·x + sy·y + ½`` (never zero in
integers; the midpoint circle algorithm in its 4-connected form). Of all grid nodes on the
diagonal through both candidates it takes the one nearest to where the circle crosses that
diagonal (nodes there are √2 apart and ``|∇r| = 1``), so every node keeps
``|r − R| ≤ √2/2`` step, each axis is crossed at ``±round(R)`` and a full circle takes
exactly ``8·round(R)`` steps. Quadrants are half-open in the direction of motion (a node on
an axis belongs to the quadrant the arc is entering) and change when the inward coordinate
reaches zero, so arcs may cross any number of quadrant boundaries; ``start == end`` is a
full circle. The end point may lie up to one step off the circle through the start point:
in the last quadrant no axis is stepped past its end coordinate, which lands the staircase
exactly on the end point; the bounds then read ``max(1, e)`` and ``max(√2/2, e)`` with
``e = |r_end − R|``. The tests prove all of these by brute force (radius ≤ 60).

On every axis-parallel unit edge the distance to a line and the radius are largest at an end
(the distance is convex along the edge; the radius has its minimum at the foot of the
perpendicular from the centre, which never lies strictly inside an edge between integer
nodes), so the deviation of the whole staircase is the deviation of its nodes.

Typical use::

    steps = of_linear_extrapolated(5, 3)      # [(1, 0), (0, 1), (1, 0), ...]
    nodes = path_nodes(steps)                  # (9, 2) visited grid nodes, from (0, 0)
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import numpy as np

__all__ = [
    "ARC_END_TOLERANCE",
    "dda_linear",
    "of_arc",
    "of_arc_extrapolated",
    "of_linear",
    "of_linear_extrapolated",
    "path_nodes",
]

Step = tuple[int, int]

# Step signs (sx, sy) of a counter-clockwise move in quadrants Q1..Q4; clockwise is the
# negation. Counter-clockwise the inward axis is x in Q1/Q3 and y in Q2/Q4; clockwise the
# other way round.
_CCW_SIGNS = ((-1, 1), (-1, -1), (1, -1), (1, 1))

ARC_END_TOLERANCE = 1.0
"""How far the end point of an arc may lie off the circle through the start point (step)."""


def _as_int(name: str, value: object) -> int:
    """The value as a Python int; bool and non-integral numbers are refused."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer number of steps, got {value!r}")
    return int(value)


def _sign(value: int) -> int:
    return (value > 0) - (value < 0)


# ----------------------------------------------------------------------------- lines
def _line(xe: int, ye: int, *, extrapolated: bool) -> list[Step]:
    xe, ye = _as_int("xe", xe), _as_int("ye", ye)
    a, b = abs(xe), abs(ye)
    step_x, step_y = (_sign(xe) or 1, 0), (0, _sign(ye) or 1)
    # D = 2F, F = a·y − b·x; the extrapolated rule looks at F(x + ½, y + ½) = F + (a − b)/2.
    lead = a - b if extrapolated else 0
    d = 0
    x = y = 0
    out: list[Step] = []
    for _ in range(a + b):
        if y == b or (x < a and d + lead >= 0):
            out.append(step_x)
            x += 1
            d -= 2 * b
        else:
            out.append(step_y)
            y += 1
            d += 2 * a
    return out


def of_linear(xe: int, ye: int) -> list[Step]:
    """Classic evaluation-function (OF) line interpolator (seed 003).

    Parameters
    ----------
    xe, ye : int
        End point relative to the start (step); any signs.

    Returns
    -------
    list of (int, int)
        ``|xe| + |ye|`` unit steps ``(±1, 0)`` / ``(0, ±1)``; their sum is ``(xe, ye)``.
        Seed 003's worked example ``(5, 3)`` gives X Y X Y X X Y X.

    Notes
    -----
    Works on ``a = |xe|, b = |ye|``: ``F = 0``; ``F ≥ 0`` → X step, ``F −= b``; else Y step,
    ``F += a``. Every node is within ``max(a, b)/√(a² + b²) < 1`` step of the line.
    """
    return _line(xe, ye, extrapolated=False)


def of_linear_extrapolated(xe: int, ye: int) -> list[Step]:
    """Extrapolated OF line interpolator (seed 002): sign of F half a step ahead.

    Parameters
    ----------
    xe, ye : int
        End point relative to the start (step); any signs.

    Returns
    -------
    list of (int, int)
        ``|xe| + |ye|`` unit steps summing to ``(xe, ye)``.

    Notes
    -----
    Steps X when ``F(x + ½, y + ½) = F + (a − b)/2 ≥ 0``. On every anti-diagonal
    ``|x| + |y| = k`` the visited node is the one nearest to the line, which makes the
    maximum normal deviation, ``≤ (a + b)/(2·√(a² + b²)) ≤ √2/2`` step, the smallest any
    monotone unit-step path can have.
    """
    return _line(xe, ye, extrapolated=True)


def dda_linear(xe: int, ye: int, *, bits: int | None = None, preload: bool = False
               ) -> list[Step]:
    """Digital differential analyser: two accumulators of ``bits`` width.

    Each clock adds ``|xe|`` and ``|ye|`` to their accumulators; an overflow past
    ``2**bits`` emits a pulse on that axis. After ``2**bits`` clocks each axis has emitted
    exactly ``|xe|`` / ``|ye|`` pulses.

    Parameters
    ----------
    xe, ye : int
        End point relative to the start (step); any signs.
    bits : int, optional
        Register width (bit). Default: the smallest width with ``2**bits ≥ max(|xe|, |ye|)``
        (at least 1).
    preload : bool
        Start both accumulators at half the register instead of zero, so that positions are
        rounded rather than truncated.

    Returns
    -------
    list of (int, int)
        One tuple per clock that produced a pulse: ``(±1, 0)``, ``(0, ±1)``, or the diagonal
        ``(±1, ±1)`` when both axes pulse in the same clock (idle clocks are left out). The
        sum is ``(xe, ye)``.

    Raises
    ------
    ValueError
        If ``bits < 1`` or the register cannot hold ``max(|xe|, |ye|)``.

    Notes
    -----
    After clock k the position is ``floor((k·a + p)/2**bits)`` per axis (``p`` the preload),
    so each axis trails the ideal point ``k·a/2**bits`` by less than one step (at most half
    a step with ``preload``), and the normal deviation from the line is below
    ``max(a, b)/√(a² + b²) ≤ 1`` step (``(a + b)/(2·√(a² + b²)) ≤ √2/2`` with ``preload``).
    """
    xe, ye = _as_int("xe", xe), _as_int("ye", ye)
    a, b = abs(xe), abs(ye)
    largest = max(a, b)
    if bits is None:
        bits = max(1, (largest - 1).bit_length())
    bits = _as_int("bits", bits)
    if bits < 1 or (1 << bits) < largest:
        raise ValueError(f"bits = {bits}: a register of 2**bits must hold max(|xe|, |ye|) = "
                         f"{largest} and bits must be at least 1")
    if largest == 0:
        return []
    capacity = 1 << bits
    sx, sy = _sign(xe), _sign(ye)
    acc_x = acc_y = capacity // 2 if preload else 0
    out: list[Step] = []
    for _ in range(capacity):
        acc_x += a
        acc_y += b
        dx = dy = 0
        if acc_x >= capacity:
            acc_x -= capacity
            dx = sx
        if acc_y >= capacity:
            acc_y -= capacity
            dy = sy
        if dx or dy:
            out.append((dx, dy))
    return out


# ------------------------------------------------------------------------------ arcs
def _quadrant(x: int, y: int, ccw: bool) -> int:
    """Index 0..3 (Q1..Q4) of a node, half-open in the direction of motion."""
    if ccw:
        if x > 0 and y >= 0:
            return 0
        if x <= 0 and y > 0:
            return 1
        if x < 0 and y <= 0:
            return 2
        return 3
    if x >= 0 and y > 0:
        return 0
    if x < 0 and y >= 0:
        return 1
    if x <= 0 and y < 0:
        return 2
    return 3


def _arc(x0: int, y0: int, xe: int, ye: int, *, ccw: bool, center: Sequence[int],
         extrapolated: bool) -> list[Step]:
    x0, y0 = _as_int("x0", x0), _as_int("y0", y0)
    xe, ye = _as_int("xe", xe), _as_int("ye", ye)
    cx, cy = (_as_int("center[0]", center[0]), _as_int("center[1]", center[1]))
    x, y = x0 - cx, y0 - cy
    ex, ey = xe - cx, ye - cy
    r2 = x * x + y * y
    if r2 < 2:
        raise ValueError(f"start ({x0}, {y0}) is {math.sqrt(r2):g} step from the centre "
                         f"({cx}, {cy}); a unit-step arc needs a radius of at least √2 step")
    radius, end_radius = math.sqrt(r2), math.hypot(ex, ey)
    if abs(end_radius - radius) > ARC_END_TOLERANCE:
        raise ValueError(
            f"end ({xe}, {ye}) is {end_radius:.4f} step from the centre ({cx}, {cy}) but the "
            f"start ({x0}, {y0}) is {radius:.4f}: not on one circle within "
            f"{ARC_END_TOLERANCE:g} step")

    turn = 1 if ccw else -1
    q, q_end = _quadrant(x, y, ccw), _quadrant(ex, ey, ccw)
    crossings = ((q_end - q) * turn) % 4
    if crossings == 0:
        cross = x * ey - y * ex
        behind = cross * turn < 0 or (cross == 0 and (ex, ey) == (x, y))
        if behind:  # the end lies behind the start in its quadrant, or a full circle
            crossings = 4

    f = 0  # x² + y² − R², exact at the start
    out: list[Step] = []
    while True:
        sx, sy = (turn * s for s in _CCW_SIGNS[q])
        inward_is_x = (q % 2 == 0) == ccw
        if crossings == 0:  # last quadrant: never step an axis past its end coordinate
            rx, ry = ex - x, ey - y
            if rx == 0 and ry == 0:
                return out
            if rx == 0 or ry == 0 or _sign(rx) != sx or _sign(ry) != sy:
                # One axis is done, or the end lies a fraction of a step across the
                # boundary: walk straight to it, the off-side axis first.
                step_x = ry == 0 or (rx != 0 and _sign(rx) != sx)
                sx, sy = _sign(rx), _sign(ry)
                inward = None
            else:
                inward = _inward(f, x, y, sx, sy, extrapolated)
                step_x = inward == inward_is_x
        else:
            inward = _inward(f, x, y, sx, sy, extrapolated)
            step_x = inward == inward_is_x
        if step_x:
            f += 2 * sx * x + 1
            x += sx
            out.append((sx, 0))
        else:
            f += 2 * sy * y + 1
            y += sy
            out.append((0, sy))
        if inward and crossings and (x if inward_is_x else y) == 0:
            q = (q + turn) % 4
            crossings -= 1


def _inward(f: int, x: int, y: int, sx: int, sy: int, extrapolated: bool) -> bool:
    """The OF decision: True → step the inward axis, False → the outward one."""
    if extrapolated:  # 2·F(x + sx/2, y + sy/2) = 2F + 2(sx·x + sy·y) + 1, odd: no ties
        return 2 * (f + sx * x + sy * y) + 1 > 0
    return f >= 0


def of_arc(x0: int, y0: int, xe: int, ye: int, *, ccw: bool,
           center: Sequence[int] = (0, 0)) -> list[Step]:
    """Classic evaluation-function circular interpolator, ``F = x² + y² − R²``.

    Parameters
    ----------
    x0, y0 : int
        Start point (step), on the grid; it defines the radius R.
    xe, ye : int
        End point (step); within one step of the circle. ``(xe, ye) == (x0, y0)`` is a full
        circle.
    ccw : bool
        Counter-clockwise (G03) if True, clockwise (G02) otherwise.
    center : (int, int)
        Centre of the circle (step).

    Returns
    -------
    list of (int, int)
        Unit steps from the start to exactly the end point.

    Raises
    ------
    ValueError
        If the radius is below √2 step or the end point is more than one step off the
        circle (the message gives both radii).

    Notes
    -----
    Steps towards the centre when ``F ≥ 0`` and away from it otherwise; every node keeps
    ``|r − R| ≤ 1`` step.
    """
    return _arc(x0, y0, xe, ye, ccw=ccw, center=center, extrapolated=False)


def of_arc_extrapolated(x0: int, y0: int, xe: int, ye: int, *, ccw: bool,
                        center: Sequence[int] = (0, 0)) -> list[Step]:
    """Extrapolated OF circular interpolator (seed 002): sign of F half a step ahead.

    Parameters and errors as for :func:`of_arc`.

    Returns
    -------
    list of (int, int)
        Unit steps from the start to exactly the end point.

    Notes
    -----
    Steps towards the centre when ``F(x + sx/2, y + sy/2) > 0``, ``(sx, sy)`` the step
    signs of the quadrant: the candidate nearer to the circle along the diagonal through
    both is chosen, and every node keeps ``|r − R| ≤ √2/2`` step.
    """
    return _arc(x0, y0, xe, ye, ccw=ccw, center=center, extrapolated=True)


def path_nodes(steps: Sequence[Step], *, start: Sequence[int] = (0, 0)) -> np.ndarray:
    """Grid nodes visited by a step sequence, the start included.

    Parameters
    ----------
    steps : sequence of (int, int)
        Steps as returned by the interpolators (step).
    start : (int, int)
        The first node (step).

    Returns
    -------
    ndarray, shape (len(steps) + 1, 2), int64
        ``start`` followed by the running sums of the steps (step).
    """
    nodes = np.zeros((len(steps) + 1, 2), dtype=np.int64)
    nodes[0] = start
    if steps:
        nodes[1:] = np.cumsum(np.asarray(steps, dtype=np.int64), axis=0) + nodes[0]
    return nodes
