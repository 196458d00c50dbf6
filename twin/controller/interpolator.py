"""Equal-time interpolator: per-tick position, velocity, acceleration and jerk references.

Every period T the interpolator advances the active block's speed profile (its law, planned
by the look-ahead planner) by T and maps the path state (s, ṡ, s̈, s⃛) through the geometry —
seed 004's *extended interface*: the regulator gets float64 velocity, acceleration and jerk
alongside the position, never differences of integer positions::

    p = point(s)
    v = ṡ·t̂
    a = s̈·t̂ + ṡ²κ·n̂
    j = s⃛·t̂ + 3ṡs̈κ·n̂ + ṡ³(κ'·n̂ − κ²·t̂)

(t̂ the unit tangent, n̂ = t̂ turned +90°, κ the signed curvature, κ' = dκ/ds). Lines and
arcs are evaluated on floats (lines inline, arcs by ``geometry.arc_point``, the one arc
evaluation, shared with ``Arc.frame`` and the compiled kernel); other segments through
``Segment.frame(s)``, which gives the point, tangent, κ and κ' of a spline in one call.

A tick that crosses a block end carries the leftover time into the next block (or dwell), so
the path time is continuous. When the program ends the reference lands *exactly* on the
programmed end point (the segment's ``end``, not a sum of increments) with v = a = j = 0.

``mode="traditional"`` reproduces the classic interface for comparison: the position is
rounded to whole encoder counts and v, a, j are backward differences of those rounded
positions (seed 004: feed ripple of ±1 count per tick, one-tick acceleration spikes).

Cyclic cost: the next block is fetched from the planner and its profile planned in the ticks
*before* it is needed, one step per tick (``prepare``), so a block change costs a tick about
as much as any other tick. The status follows Ruckig: ``WORKING`` … ``FINISHED``.

Typical use (a 10 mm line at 600 mm/min on tomsk_xy, from the origin, outside its work
zone: no soft limits; the reference ends exactly on the programmed end point, at rest)::

    >>> from twin.config import load_machine
    >>> from twin.controller.gcode import parse
    >>> from twin.controller.planner import Planner
    >>> cfg = load_machine("tomsk_xy")
    >>> planner = Planner.from_settings(cfg.controller, cfg.axes, work_zone=None)  # no soft limits
    >>> program = parse("G21 G90 G1 X10 Y0 F600", start=(0.0, 0.0))
    >>> interp = Interpolator(planner.plan(program), period=5e-3)
    >>> ticks = 0
    >>> while interp.update() < InterpolatorStatus.FINISHED:
    ...     ref = interp.reference      # .position, .velocity, .acceleration, .jerk (2,)
    ...     ticks += 1
    >>> ticks, interp.reference.position.tolist(), interp.reference.velocity.tolist()
    (221, [0.01, 0.0], [0.0, 0.0])
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from twin.controller.cyclic import block_tables
from twin.controller.gcode.items import Dwell
from twin.controller.geometry import Arc, Line, Segment, arc_point
from twin.controller.planner import PlannedBlock
from twin.controller.profiles import min_distance, plan_move
from twin.errors import ConfigError, TwinError

__all__ = ["INTERPOLATOR_MODES", "Interpolator", "InterpolatorStatus", "Reference"]

INTERPOLATOR_MODES = ("extended", "traditional")
"""``Interpolator(mode=...)``: float channels, or integer counts and finite differences."""

_LINE, _ARC, _CURVE, _DWELL = 0, 1, 2, 3


class InterpolatorStatus(IntEnum):
    """State of the interpolator after an update (ordered: ≥ FINISHED means at rest)."""

    WORKING = 0
    """Moving along a block."""
    DWELLING = 1
    """Standing still for a G4 dwell."""
    FINISHED = 2
    """Every block done; the reference is on the programmed end point."""
    ERROR = 3
    """The block source failed (``Interpolator.error``); holding at rest where it ended."""


def _zeros() -> np.ndarray:
    return np.zeros(2)


@dataclass(slots=True)
class Reference:
    """The interpolator's output for one tick (arrays written in place each tick).

    Attributes
    ----------
    position : ndarray, shape (2,)
        Position reference (m).
    velocity : ndarray, shape (2,)
        Velocity reference (m/s).
    acceleration : ndarray, shape (2,)
        Acceleration reference (m/s²).
    jerk : ndarray, shape (2,)
        Jerk reference (m/s³).
    time : float
        Time since the start (s).
    block : int
        Index of the active motion block, −1 before the first.
    line : int
        Source line of the active block or dwell (0 if none).
    status : InterpolatorStatus
        As returned by ``update``.
    """

    position: np.ndarray = field(default_factory=_zeros)
    velocity: np.ndarray = field(default_factory=_zeros)
    acceleration: np.ndarray = field(default_factory=_zeros)
    jerk: np.ndarray = field(default_factory=_zeros)
    time: float = 0.0
    block: int = -1
    line: int = 0
    status: InterpolatorStatus = InterpolatorStatus.WORKING


class _Active:
    """A prepared block or dwell (internal)."""

    __slots__ = ("block", "cx", "cy", "duration", "end", "index", "k", "kind", "line",
                 "profile", "r", "s0", "segment", "sign", "tables", "th0", "ux", "uy", "x0",
                 "y0")


class Interpolator:
    """Equal-time interpolation of planned blocks (see the module docstring).

    Parameters
    ----------
    blocks : iterable
        ``PlannedBlock``s, ``Dwell``s and pass-through items (events, program end), e.g.
        ``Planner.plan(program)``; consumed lazily.
    period : float
        Tick period T (s).
    start : sequence of 2 float, optional
        Where the reference stands before the first block (m); default its start point.
    mode : {"extended", "traditional"}
        See the module docstring.
    counts_per_metre : sequence of 2 float, optional
        Encoder resolution per axis (counts/m); required for ``"traditional"``.
    on_event : callable, optional
        Called as ``on_event(time, item)`` when a pass-through item is reached.
    tables : bool
        Give every block and dwell the flat arrays of the compiled tick
        (``cyclic.block_tables``, as ``tables`` of the active state; None where the kernel
        cannot run it). Off, nothing is built.
    """

    def __init__(self, blocks: Iterable[Any], *, period: float = 5e-3,
                 start: Sequence[float] | None = None, mode: str = "extended",
                 counts_per_metre: Sequence[float] | None = None,
                 on_event: Callable[[float, Any], None] | None = None, tables: bool = False):
        if not (math.isfinite(period) and period > 0.0):
            raise ConfigError("period", f"must be finite and > 0 (s), got {period!r}")
        if mode not in INTERPOLATOR_MODES:
            raise ConfigError("mode", f"must be one of {INTERPOLATOR_MODES}, got {mode!r}")
        if mode == "traditional":
            if counts_per_metre is None or len(counts_per_metre) != 2 or not all(
                    math.isfinite(c) and c > 0 for c in counts_per_metre):
                raise ConfigError("counts_per_metre", "traditional mode needs 2 values > 0 "
                                  f"(counts/m), got {counts_per_metre!r}")
            self._cpm = [float(c) for c in counts_per_metre]
        self.period = float(period)
        self.mode = mode
        self.on_event = on_event
        self._tables = tables
        self.read_ahead = True
        """bool: ``update`` ends with the read-ahead (``prepare_next``). A real-time
        loop that keeps its tick short sets it False and calls ``prepare_next`` itself once
        the outputs are written; the blocks and the reference are the same either way."""
        self.reference = Reference()
        """Reference: the output of the last ``update``."""
        self.error: TwinError | None = None
        """The exception the block source raised, if any (status ``ERROR``)."""
        self.events: deque[tuple[float, Any]] = deque(maxlen=1024)
        """The latest pass-through items reached, as (time, item)."""
        self._source = iter(blocks)
        self._exhausted = False
        self._ready: deque[Any] = deque()
        self._ticks = 0
        self._tau = 0.0
        self._cur: _Active | None = None
        self.prepare_next()
        if start is None:
            start = self._first_start()
        self._hold = (float(start[0]), float(start[1]))
        self.reference.position[:] = self._hold
        self._cur = self._advance()
        self._prev = list(self._hold)
        if mode == "traditional":
            self._prev = [round(p * c) / c for p, c in zip(self._hold, self._cpm, strict=True)]
            self.reference.position[:] = self._prev
        self._prev_v = [0.0, 0.0]
        self._prev_a = [0.0, 0.0]
        self.reference.status = self.status

    # ------------------------------------------------------------------ public
    @property
    def status(self) -> InterpolatorStatus:
        """Status of the active state (before any update: of the first one)."""
        cur = self._cur
        if cur is None:
            return InterpolatorStatus.ERROR if self.error else InterpolatorStatus.FINISHED
        return InterpolatorStatus.DWELLING if cur.kind == _DWELL else InterpolatorStatus.WORKING

    @property
    def time(self) -> float:
        """Time of the last update (s): ticks × period."""
        return self._ticks * self.period

    def update(self) -> InterpolatorStatus:
        """Advance one period and write ``reference``.

        Returns
        -------
        InterpolatorStatus
            ``WORKING``/``DWELLING`` while the program runs, then ``FINISHED`` (or ``ERROR``)
            for ever after, holding the end point.
        """
        self._ticks += 1
        cur = self._cur
        tau = self._tau + self.period
        changed = False
        while cur is not None and tau >= cur.duration:
            tau -= cur.duration
            self._hold = cur.end
            cur = self._cur = self._advance()
            changed = True
        self._tau = tau
        ref = self.reference
        ref.time = self._ticks * self.period
        if cur is None or cur.kind == _DWELL:
            x, y = self._hold
            vx = vy = ax = ay = jx = jy = 0.0
        else:
            x, y, vx, vy, ax, ay, jx, jy = self._evaluate(cur, tau)
        if cur is not None:
            ref.block, ref.line = cur.index, cur.line
        if self.mode == "traditional":
            x, y, vx, vy, ax, ay, jx, jy = self._differences(x, y)
        p, v, a, j = ref.position, ref.velocity, ref.acceleration, ref.jerk
        p[0] = x
        p[1] = y
        v[0] = vx
        v[1] = vy
        a[0] = ax
        a[1] = ay
        j[0] = jx
        j[1] = jy
        status = ref.status = self.status
        if not changed and self.read_ahead:
            self.prepare_next()
        return status

    def prepare_next(self) -> None:
        """Read ahead until the items ready cover the next period: fetch them from the
        block source (the streamed planner's work) and, for blocks, make their profiles and
        tables. The tick that reaches a block then only switches to it (``landing``). Stops
        at an item that is no block (an event, a dwell, the end): ``update`` runs those."""
        ready = self._ready
        while True:
            ahead = 0.0
            for item in ready:
                if type(item) is not _Active:
                    return
                ahead += item.duration
            if ahead >= self.period:
                return
            item = self._pull()
            if item is None:
                return
            ready.append(item)

    def landing(self, tau: float) -> tuple[int, _Active, float] | None:
        """Where ``update`` would land when the active block ends before ``tau`` (s into
        it): (blocks passed, the block landed in, the time into it), if every block on
        the way is read ahead and activated; None otherwise (the change needs ``update``).
        The arithmetic is ``update``'s, step by step."""
        cur, passed = self._cur, 0
        for item in self._ready:
            if type(item) is not _Active or cur is None:
                return None
            tau -= cur.duration
            cur = item
            passed += 1
            if tau < cur.duration:
                return passed, cur, tau
        return None

    def switch_blocks(self, passed: int, tau: float) -> None:
        """Make the block changes of a ``landing``: each passed block's end becomes the
        held point, and the landing block becomes active at ``tau`` (s) into it. For the
        compiled tick, which evaluates the new block itself."""
        for _ in range(passed):
            self._hold = self._cur.end  # type: ignore[union-attr]
            self._cur = self._ready.popleft()
        self._tau = tau

    def stop(self) -> None:
        """Brake to rest along the active block now and drop the rest of the program.

        The braking is one speed change of the block's law from the present speed (its
        acceleration at this instant is not carried over: a step of at most the block's
        acceleration limit). Used by homing and by a feed hold that abandons the program.
        Lines and arcs are extended beyond their end if the braking needs more room.
        """
        cur = self._cur
        self._ready.clear()
        self._exhausted = True
        close = getattr(self._source, "close", None)
        if close is not None:
            close()
        if cur is None:
            return
        if cur.kind == _DWELL:
            self._cur = None
            return
        s, v, _, _ = cur.profile.at(self._tau)
        block = cur.block
        d = min_distance(block.law, v, 0.0, block.limits)
        stop = _Active()
        for name in _Active.__slots__:
            if hasattr(cur, name):
                setattr(stop, name, getattr(cur, name))
        stop.s0 = cur.s0 + s
        stop.profile = plan_move(block.law, d, v_start=v, v_end=0.0, v_max=v,
                                 limits=block.limits)
        stop.duration = stop.profile.duration
        stop.end = self._evaluate(stop, stop.duration)[:2]
        stop.tables = block_tables(stop) if self._tables else None
        self._tau = 0.0
        if stop.duration <= 0.0:
            self._hold = stop.end
            self._cur = None
        else:
            self._cur = stop

    # ------------------------------------------------------------------ internals
    def _pull(self) -> Any:
        """Next item of the block source, a block made ready to run (``_activate``); None
        when the source is exhausted or failed."""
        if self._exhausted:
            return None
        try:
            item = next(self._source)
        except StopIteration:
            self._exhausted = True
            return None
        except TwinError as exc:
            self._exhausted = True
            self.error = exc
            return None
        return self._activate(item) if isinstance(item, PlannedBlock) else item

    def _first_start(self) -> tuple[float, float]:
        """Start point of the first block (m), reading past leading events; (0, 0) if none."""
        while True:
            for item in self._ready:
                if type(item) is _Active:
                    return float(item.segment.start[0]), float(item.segment.start[1])
            item = self._pull()
            if item is None:
                return 0.0, 0.0
            self._ready.append(item)

    def _advance(self) -> _Active | None:
        """The next block or dwell to run (events on the way are reported)."""
        while True:
            if self._ready:
                item = self._ready.popleft()
            else:
                item = self._pull()
                if item is None:
                    return None
            if isinstance(item, _Active):
                return item
            if isinstance(item, Dwell):
                if item.duration > 0.0:
                    return self._dwell(item)
                continue
            self.events.append((self.time, item))
            if self.on_event is not None:
                self.on_event(self.time, item)

    def _dwell(self, item: Dwell) -> _Active:
        act = _Active()
        act.kind, act.duration, act.end = _DWELL, item.duration, self._hold
        act.index, act.line = self.reference.block, item.line
        act.tables = block_tables(act) if self._tables else None
        return act

    def _activate(self, block: PlannedBlock) -> _Active:
        seg: Segment = block.segment
        act = _Active()
        act.block, act.segment, act.index, act.line, act.s0 = (block, seg, block.index,
                                                                block.line, 0.0)
        act.profile = block.profile()
        act.duration = act.profile.duration
        act.end = (float(seg.end[0]), float(seg.end[1]))
        act.x0, act.y0 = float(seg.start[0]), float(seg.start[1])
        if type(seg) is Line:
            act.kind = _LINE
            act.ux, act.uy = seg._ux, seg._uy
        elif type(seg) is Arc:
            act.kind = _ARC
            act.cx, act.cy, act.r = float(seg.center[0]), float(seg.center[1]), seg.radius
            act.sign = 1.0 if seg.ccw else -1.0
            act.k = act.sign / seg.radius
            act.th0 = math.atan2(act.y0 - act.cy, act.x0 - act.cx)
        else:
            act.kind = _CURVE
        act.tables = block_tables(act) if self._tables else None
        return act

    def _evaluate(self, cur: _Active, tau: float) -> tuple[float, ...]:
        s, v, a, j = cur.profile.at(tau)
        s += cur.s0
        kind = cur.kind
        if kind == _LINE:
            ux, uy = cur.ux, cur.uy
            return (cur.x0 + s * ux, cur.y0 + s * uy, v * ux, v * uy, a * ux, a * uy,
                    j * ux, j * uy)
        if kind == _ARC:
            k = cur.k
            x, y, tx, ty = arc_point(cur.cx, cur.cy, cur.r, cur.th0, k, cur.sign, s)
            dk = 0.0
        else:
            x, y, tx, ty, k, dk = cur.segment.frame(s)
        nx, ny = -ty, tx
        an = v * v * k                                   # centripetal acceleration
        jt = j - v * v * v * k * k                       # tangential jerk
        jn = 3.0 * v * a * k + v * v * v * dk            # normal jerk
        return (x, y, v * tx, v * ty, a * tx + an * nx, a * ty + an * ny,
                jt * tx + jn * nx, jt * ty + jn * ny)

    def _differences(self, x: float, y: float) -> tuple[float, ...]:
        """Traditional interface: whole counts, derivatives by backward differences."""
        out = []
        inv_t = 1.0 / self.period
        for k, p in enumerate((x, y)):
            c = self._cpm[k]
            q = round(p * c) / c
            v = (q - self._prev[k]) * inv_t
            a = (v - self._prev_v[k]) * inv_t
            out.append((q, v, a, (a - self._prev_a[k]) * inv_t))
            self._prev[k], self._prev_v[k], self._prev_a[k] = q, v, a
        (x, vx, ax, jx), (y, vy, ay, jy) = out
        return x, y, vx, vy, ax, ay, jx, jy
