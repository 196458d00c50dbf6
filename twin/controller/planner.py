"""Look-ahead feed planner (seed 001): node and segment speeds over a bounded window.

Seed 001 assigns every node (junction of two blocks) and every segment the highest speed
that all three kinds of limit allow::

    V_node    = min(V_node_tech, V_node_accuracy, V_node_length)
    V_segment = min(V_seg_tech,  V_seg_accuracy,  V_seg_length)

* technological: the programmed feed of both blocks at a node (the rapid speed for G0);
* accuracy: at a node, the corner model ``tolerance / δ*(angle)`` (`twin.controller.corner`);
  on a segment, the per-axis velocity limits projected on its direction, the contour
  ``max_velocity``, and on curved segments the centripetal acceleration and the jerk;
* length: every block must be able to brake before the end of the look-ahead window, which
  is assumed to end at rest (backward pass), and every node must be reachable from the one
  before it (forward pass), both with the chosen acceleration law: `max_end_speed`, made
  monotone in the start speed by `twin.controller.reach` (without that, raising one node
  could shrink what its neighbour may do, and the incremental passes would be unsound).

Streaming and incremental
-------------------------
``Planner.plan(items)`` is a generator: it reads motion items one at a time, holds at most
``lookahead`` blocks, and yields each block once it leaves the window, so a program of any
length is planned in constant memory. Like grbl's ``planner.c`` it re-plans incrementally.
For each node it keeps ``fw``, the forward envelope (the speed reachable from the window's
fixed start, capped by the node limit), which never changes once computed, and the planned
entry speed ``entry = min(fw, g(next entry, length))`` (g the monotone reach). Appending a
block only *raises* entries (the window's end moves away), so the backward pass walks from the
newest block and stops at the first entry that does not change: typically after one or two
blocks. When a block leaves the window the next block's entry is committed; if that lowers
a forward envelope the change is propagated forward until it stops mattering.

Blocks therefore come out identical for any window that covers the braking distance (the
backward pass from the window's end saturates before it reaches the block).

Decisions
---------
* The machine starts at rest; nodes next to a rapid (G0) are exact stops (seed 003: G0
  brakes at block end), and so are Dwell, Event and ProgramEnd items: they flush the window
  and pass through in order. Nothing after a ProgramEnd is read.
* Contour ``max_velocity`` limits feed moves; rapids are limited by ``rapid_velocity`` and
  the per-axis limits only.
* Segment caps (per-axis projections, centripetal acceleration and jerk on curves) are
  computed by `twin.controller.segment_limits`.
* Soft limits: with a ``work_zone`` every segment's bounding box is checked when it enters
  the window. A violation (or a G-code error in a streamed file) stops reading: the blocks
  already in the window are still yielded — they were planned to end at rest — and then the
  ``PlanningError`` naming the G-code line is raised. ``check`` runs the same test over a
  whole in-memory program before any motion.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

from twin.config import AxisConfig, ControllerSettings
from twin.controller.corner import CornerModel, SeedCornerModel
from twin.controller.gcode.items import Dwell, Move, ProgramEnd
from twin.controller.geometry import Arc, Line, Segment
from twin.controller.profiles import Limits, Profile, plan_move
from twin.controller.profiles.laws import check_law
from twin.controller.reach import monotone_end_speed as reach_speed
from twin.controller.reach import reach_floor
from twin.controller.segment_limits import SegmentLimits
from twin.controller.workzone import WorkZone
from twin.errors import ConfigError, PlanningError, TwinError

__all__ = [
    "MODES",
    "MotionBlock",
    "PlannedBlock",
    "Planner",
    "segment_of",
    "segments_from_program",
]

MODES = ("lookahead", "stop")
"""``Planner(mode=...)``: look-ahead speeds, or the classic stop at every node."""

@dataclass(frozen=True, slots=True)
class MotionBlock:
    """A segment to travel at a programmed feed: the planner's motion input.

    Attributes
    ----------
    segment : Segment
        The path piece (m).
    feed : float or None
        Programmed contour feed (m/s); None for a rapid (the machine's rapid speed).
    line : int
        Source line for messages (0 when not from a program).
    """

    segment: Segment
    feed: float | None
    line: int = 0


class PlannedBlock(NamedTuple):
    """One block with its planned speeds (an immutable tuple: cheap to make per block).

    Attributes
    ----------
    segment : Segment
        The path piece (m).
    feed : float or None
        Programmed feed (m/s), None for a rapid.
    v_start, v_nominal, v_end : float
        Speed at the start node, the segment's speed cap, speed at the end node (m/s).
    law : str
        Acceleration law.
    limits : Limits
        Tangential limits on this segment (m/s, m/s², m/s³); ``max_velocity == v_nominal``.
    line : int
        Source line (0 when not from a program).
    index : int
        0-based number of the motion block in the program.
    """

    segment: Segment
    feed: float | None
    v_start: float
    v_nominal: float
    v_end: float
    law: str
    limits: Limits
    line: int
    index: int

    @property
    def rapid(self) -> bool:
        """True for a G0 block."""
        return self.feed is None

    def profile(self) -> Profile:
        """The block's speed profile along its segment (``plan_move`` of its law)."""
        return plan_move(self.law, self.segment.length, v_start=self.v_start,
                         v_end=self.v_end, v_max=self.v_nominal, limits=self.limits)


def segment_of(move: Move) -> Segment | None:
    """The ``Line`` or ``Arc`` of a G-code ``Move``; None for a zero-length line."""
    if move.kind == "arc":
        return Arc(move.start, move.end, move.center, ccw=move.ccw, turns=move.turns)
    if move.start == move.end:
        return None
    return Line(move.start, move.end)


def segments_from_program(items: Iterable[Any]) -> Iterator[Any]:
    """Turn G-code ``Move`` items into ``MotionBlock``s of ``Line``/``Arc`` segments.

    ``MotionBlock``s, Dwell, Event and ProgramEnd items pass through unchanged; zero-length
    lines are dropped. Lazy: consumes ``items`` (a ``Program`` or any iterable, e.g.
    ``gcode.read_file``) one at a time.
    """
    for item in items:
        if type(item) is Move:
            seg = segment_of(item)
            if seg is not None:
                yield MotionBlock(seg, item.feed, item.line)
        else:
            yield item


class _Block:
    """A block in the window: its geometry summary and its speeds (mutable, internal)."""

    __slots__ = ("entry", "feed", "floor", "fw", "index", "length", "limits", "line", "rapid",
                 "segment", "t0x", "t0y", "t1x", "t1y", "v_nom")


class Planner:
    """Seed-001 speed assignment with a bounded look-ahead window (see the module doc).

    Parameters
    ----------
    limits : Limits
        Contour limits (m/s, m/s², m/s³); ``max_velocity`` caps the feed moves.
    axis_limits : sequence of 2 Limits
        Limits of the x and y axes, projected on each segment's direction.
    rapid_velocity : float
        Speed of G0 moves (m/s).
    tolerance : float
        Allowed contour error at corners δ_allowed (m).
    law : str
        Acceleration law, one of ``twin.controller.profiles.LAWS``.
    lookahead : int
        Window size (blocks), ≥ 1. 1 means stop at every node.
    mode : {"lookahead", "stop"}
        ``"stop"`` plans every node at rest (the classic controller, for comparison).
    corner_model : CornerModel, optional
        Node speed limit from the corner angle; default ``SeedCornerModel()``.
    work_zone : WorkZone, optional
        Soft limits; None: unchecked.
    min_feed : float
        Slowest programmed feed accepted (m/s): a slower one (a typing slip, a number that
        underflowed to a denormal) is a ``PlanningError`` at its line.
    max_program_time : float
        Longest a program may take (s), judged by a lower bound of its time (every block at
        its full feed, plus the dwells): the block or dwell that passes it is a
        ``PlanningError`` at its line, before the run would otherwise stop at its time
        limit with nothing said.
    """

    def __init__(self, limits: Limits, axis_limits: Sequence[Limits], *,
                 rapid_velocity: float, tolerance: float, law: str = "parabolic",
                 lookahead: int = 64, mode: str = "lookahead",
                 corner_model: CornerModel | None = None, work_zone: WorkZone | None = None,
                 min_feed: float = 1e-6, max_program_time: float = 86400.0):
        check_law(law)
        if mode not in MODES:
            raise ConfigError("mode", f"must be one of {MODES}, got {mode!r}")
        if isinstance(lookahead, bool) or not isinstance(lookahead, int) or lookahead < 1:
            raise ConfigError("lookahead", f"must be an integer >= 1, got {lookahead!r}")
        if len(axis_limits) != 2:
            raise ConfigError("axis_limits", f"need 2 (x, y), got {len(axis_limits)}")
        for name, value in (("rapid_velocity", rapid_velocity), ("tolerance", tolerance),
                            ("min_feed", min_feed), ("max_program_time", max_program_time)):
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(name, f"must be finite and > 0, got {value!r}")
        self.limits = limits
        self.axis_limits = tuple(axis_limits)
        self.rapid_velocity = float(rapid_velocity)
        self.tolerance = float(tolerance)
        self.law = law
        self.lookahead = lookahead
        self.mode = mode
        self.corner_model: CornerModel = corner_model or SeedCornerModel()
        self.work_zone = work_zone
        self._caps = SegmentLimits(limits, axis_limits)
        self._limits_cache: dict[tuple[float, float, float], Limits] = {}
        self._count = 0
        self.min_feed = float(min_feed)
        self.max_program_time = float(max_program_time)
        self._time_bound = 0.0

    @classmethod
    def from_settings(cls, settings: ControllerSettings, axes: Mapping[str, AxisConfig],
                      **options: Any) -> Planner:
        """A planner from the machine's controller settings and axes.

        Keyword options override: ``law`` (default ``settings.profile``), ``mode``
        (``settings.planner``), ``lookahead``, ``corner_model``, ``work_zone`` (default the
        axes' travel inside the limit switches when ``settings.soft_limits``, else None;
        pass None to disable), ``tolerance``.
        """
        options.setdefault("law", settings.profile)
        options.setdefault("mode", settings.planner)
        options.setdefault("lookahead", settings.lookahead)
        options.setdefault("tolerance", settings.contour_tolerance)
        options.setdefault("min_feed", settings.min_feed)
        options.setdefault("max_program_time", settings.max_program_time)
        if "work_zone" not in options:
            options["work_zone"] = WorkZone.from_axes(axes) if settings.soft_limits else None
        return cls(Limits.from_config(settings.limits),
                   [Limits.from_config(axes[a].limits) for a in "xy"],
                   rapid_velocity=settings.rapid_velocity, **options)

    # ------------------------------------------------------------------ public
    def plan(self, items: Iterable[Any]) -> Iterator[Any]:
        """Plan a stream of motion items; yield ``PlannedBlock``s and pass-through items.

        Parameters
        ----------
        items : iterable
            G-code items (``Program``, ``gcode.read_file(...)``) and/or ``MotionBlock``s.

        Yields
        ------
        PlannedBlock, Dwell, Event or ProgramEnd
            In program order.

        Raises
        ------
        PlanningError or GCodeError
            After the blocks planned before the fault (which end at rest) have been yielded.
        """
        window: deque[_Block] = deque()
        source = iter(items)
        error: TwinError | None = None
        self._count = 0
        self._time_bound = 0.0
        while True:
            try:
                item = next(source)
                kind = type(item)
                if kind is Move:                 # segments_from_program, inlined
                    seg = segment_of(item)
                    if seg is None:
                        continue
                    block = self._block(seg, item.feed, item.line)
                elif kind is MotionBlock:
                    block = self._block(item.segment, item.feed, item.line)
                else:
                    block = None
                    if kind is Dwell:
                        self._spend(item.duration, item.line, "its dwell")
            except StopIteration:
                break
            except TwinError as exc:
                error = exc
                break
            if block is not None:
                self._append(window, block)
                if len(window) >= self.lookahead:
                    yield self._pop(window)
                continue
            while window:
                yield self._pop(window)
            yield item
            if isinstance(item, ProgramEnd):
                break
        while window:
            yield self._pop(window)
        if error is not None:
            raise error

    def check(self, items: Iterable[Any]) -> None:
        """Check a whole program against the work zone before any motion.

        Raises
        ------
        PlanningError
            Naming the G-code line of the first move that leaves the zone.
        """
        self._time_bound = 0.0
        for item in segments_from_program(items):
            if type(item) is MotionBlock:
                if self.work_zone is not None:
                    self.work_zone.check(item.segment, item.line)
                self._account(item.segment.length, item.feed, item.line)
            elif type(item) is Dwell:
                self._spend(item.duration, item.line, "its dwell")

    # ------------------------------------------------------------------ internals
    def _account(self, length: float, feed: float | None, line: int) -> float:
        """The feed bound, and the block's time at full feed against the program's; returns
        that full speed (m/s): the rapid speed, or the feed capped by the contour limit."""
        if feed is not None and not feed >= self.min_feed:
            raise PlanningError(f"line {line}: feed {feed * 60e3:.6g} mm/min is below the "
                                f"machine's minimum {self.min_feed * 60e3:.6g} mm/min "
                                "(controller.min_feed)")
        v = self.rapid_velocity if feed is None else min(feed, self.limits.max_velocity)
        self._spend(length / v, line, "its moves")
        return v

    def _spend(self, seconds: float, line: int, what: str) -> None:
        self._time_bound += seconds
        if not self._time_bound <= self.max_program_time:
            raise PlanningError(f"line {line}: the program takes at least "
                                f"{self._time_bound:.6g} s with {what} so far, beyond the "
                                f"machine's {self.max_program_time:g} s "
                                "(controller.max_program_time)")

    def _block(self, seg: Segment, feed: float | None, line: int) -> _Block:
        if self.work_zone is not None:
            self.work_zone.check(seg, line)
        v_cap = self._account(seg.length, feed, line)
        b = _Block()
        b.segment, b.feed, b.line = seg, feed, line
        b.rapid = feed is None
        b.length = seg.length
        b.index = self._count
        self._count += 1
        if type(seg) is Line:
            ux, uy = seg._ux, seg._uy      # float fast path (same package)
            b.t0x = b.t1x = ux
            b.t0y = b.t1y = uy
            v_nom, acc, jerk = self._caps.line_caps(abs(ux), abs(uy), v_cap)
        else:
            b.t0x, b.t0y = (float(c) for c in seg.start_tangent)
            b.t1x, b.t1y = (float(c) for c in seg.end_tangent)
            v_nom, acc, jerk = self._caps.curve_caps(seg, v_cap)
        b.v_nom = v_nom
        key = (v_nom, acc, jerk)
        lim = self._limits_cache.get(key)
        if lim is None:
            if len(self._limits_cache) > 4096:
                self._limits_cache.clear()
            lim = self._limits_cache[key] = Limits(v_nom, acc, jerk)
        b.limits = lim
        b.floor = reach_floor(self.law, b.length, lim)
        return b

    def _append(self, window: deque[_Block], b: _Block) -> None:
        law = self.law
        prev = window[-1] if window else None
        if prev is None or self.mode == "stop" or prev.rapid or b.rapid:
            emax = 0.0
        else:
            emax = min(prev.v_nom, b.v_nom)
            cross = prev.t1x * b.t0y - prev.t1y * b.t0x
            dot = prev.t1x * b.t0x + prev.t1y * b.t0y
            corner = self.corner_model.max_node_speed(math.atan2(abs(cross), dot),
                                                      self.tolerance)
            if corner < emax:
                emax = corner
            reach = reach_speed(law, prev.fw, prev.length, prev.limits, prev.floor)
            if reach < emax:
                emax = reach
        b.fw = emax
        b.entry = -1.0
        window.append(b)
        v = 0.0
        for r in reversed(window):          # backward pass, newest first
            if r.entry == r.fw:             # at its forward cap (or committed): final
                break
            cand = reach_speed(law, v, r.length, r.limits, r.floor)
            new = r.fw if r.fw < cand else cand
            if new <= r.entry:
                break
            r.entry = v = new

    def _pop(self, window: deque[_Block]) -> PlannedBlock:
        b = window.popleft()
        v_end = 0.0
        if window:
            head = window[0]
            v_end = head.entry
            if head.fw > v_end:             # commit: the next block starts at v_end
                head.fw = v_end
                self._propagate(window)
        return PlannedBlock(b.segment, b.feed, b.entry, b.v_nom, v_end, self.law, b.limits,
                            b.line, b.index)

    def _propagate(self, window: deque[_Block]) -> None:
        """Forward pass after a lowered envelope at ``window[0]``; stops when nothing changes."""
        law = self.law
        prev = None
        for r in window:
            if prev is not None:
                cand = reach_speed(law, prev.fw, prev.length, prev.limits, prev.floor)
                if cand >= r.fw:
                    return
                r.fw = cand
                if r.entry > cand:
                    r.entry = cand
            prev = r
