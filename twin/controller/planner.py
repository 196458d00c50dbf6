"""Look-ahead feed planner (seed 001): node and segment speeds over a bounded window.

Seed 001 assigns every node (junction of two blocks) and every segment the highest speed
that all three kinds of limit allow::

    V_node    = min(V_node_tech, V_node_accuracy, V_node_length)
    V_segment = min(V_seg_tech,  V_seg_accuracy,  V_seg_length)

* technological: the programmed feed of both blocks at a node (the rapid speed for G0);
* accuracy: at a kink, the corner model ``tolerance / δ*(angle)`` (`twin.controller.corner`)
  and the velocity step the axes can take in one period (below); on a segment, the per-axis
  velocity limits projected on its direction, the contour ``max_velocity``, and on curved
  segments the centripetal acceleration and the jerk;
* length: every block must be able to brake before the end of the look-ahead window, which
  is assumed to end at rest (backward pass), and every node must be reachable from the one
  before it (forward pass), both with the chosen acceleration law: `max_end_speed`, made
  monotone in the start speed by `twin.controller.reach` (without that, raising one node
  could shrink what its neighbour may do, and the incremental passes would be unsound).

Corners: blended, or a velocity step the axes can take
------------------------------------------------------
In look-ahead mode the kinks between feed lines are first rounded by tangent arcs within
``blend`` × the contour tolerance (`twin.controller.blend`): a chorded curve becomes a
chain of arcs and runs at the centripetal limit of the curve it approximates, whatever its
chord length, and a sharp corner at the speed its blend arc allows. A kink that is not
blended (an arc meeting a line at an angle, a reversal) is passed at a speed whose velocity
step the axes can take in one controller period T, the reference's own time step::

    v · |t̂_out,k − t̂_in,k| ≤ A_k · T     for each axis k, and
    v · |t̂_out − t̂_in|    ≤ A   · T     for the contour limit A,

which is the acceleration the sampled reference shows there (a step Δv within one period
is Δv/T in its second difference), and at most the corner model's speed. For a law that
limits jerk the same step shows as Δv/T² in the third difference, so such a kink (a G61
corner, an arc meeting a line at an angle) is passed at ``v·|Δt̂_k| ≤ J_k·T²``: all but
stopped, as a jerk limit demands of a corner.

Curvature across nodes (laws that limit jerk)
---------------------------------------------
A node where the curvature steps (a line entering an arc, a circular blend, arcs of two
radii) steps the normal acceleration by ``v²·|κ_out − κ_in|`` within one period. The
sampled position shows at most 3/4 of that step in its third difference, but the
regulator's feed-forward takes the interpolator's acceleration itself, so the whole step
reaches the drive (`block_rules.STEP_SEEN` = 1): the node is passed at
``v²·|Δκ| ≤ J·T`` (J the smallest of the contour and axis jerks). Where the curvature is
continuous (a G2 blend, a spline, a chain of equal arcs) there is no such cap. A *sliver* —
a line so short after a curve that missing the curve's normal acceleration along it shows as
at most a tenth of J
(`block_rules.SLIVER_JERK`), as blends leave between the rounded chords of CAM output —
takes the curve's curvature, so the step is counted once, from the curve before it to the
curve after. On a curve the jerk budget is split as `twin.controller.segment_limits`
states (the tangential and normal components of the jerk vector, |j| ≤ J).

Runs: the smooth laws across blocks
-----------------------------------
Every law's speed change starts and ends at zero acceleration (the trapezoid excepted), so
a change confined to one block must fit inside it: over a curve sent as 0.01 mm chords a
smooth law could barely accelerate at all. For those laws consecutive blocks are planned as
one *run* when nothing at their nodes limits the speed (a tangent node, no curvature step
that binds) and joining costs little (`block_rules.RUN_CAP_SHARE`, ``RUN_LIMIT_SHARE``):
their speed caps agree within about 5 %, or the part the joining slows is short, and their
tangential limits agree within 0.6 or the part is short. The passes see the run as one
block with its lowest cap and its lowest tangential acceleration and jerk, one
``plan_move`` covers it, and each block gets its part of that move (``PlannedBlock.piece``;
the acceleration runs on across the nodes and the limits hold across them, being the
run's). A run is cut once it is as long as the view (twice the braking distance), and a
short last part of a curve is merged back into the part before it. A contour's first
chord joins its curve's run, and its last chord does when a stop follows it, where the
stop keeps the node between them too slow to bind (`BlockRules.slow_node`: a profile
from or to rest passes a node d from the stop at most at √(2·A·d)): a circle sent as
chords then runs one speed change from rest to rest, as the G3 arc does.

Stop zones: a curve next to a stop
----------------------------------
A curve's tangential limits are computed at its speed cap, where its centripetal
acceleration and curvature jerk take most of the budgets. Next to a stop (a contour's start
from rest, its end before a rapid, a dwell, an event, the program end, and every block
under G61.1) the speed is far lower, so `twin.controller.stop_zones` cuts the curve there
into zones of rising speed caps, each with the tangential limits its arcs allow up to its
cap (an arc is split at the zone's border, both parts keeping its number). The levels are
chosen per stop with the law's closed forms (the least time lost from rest to the cap); a
contour's lead chords join the first zone's run where the node to the curve cannot bind.
A G2/G3 circle and its chords then start and stop alike (issue 30: their cycle times
within 2.3 % for every law, down from 7.9-16.6 % at r = 0.5 mm). The zones hold the
blocks within half the view of a stop before the window sees them; an arc split at a zone
border leaves the planner as two blocks of the same number and line.

Streaming and incremental
-------------------------
``Planner.plan(items)`` is a generator: it reads motion items one at a time, holds at most
``lookahead`` blocks, and yields each block once it leaves the window, so a program of any
length is planned in constant memory. Like grbl's ``planner.c`` it re-plans incrementally.
For each node it keeps ``fw``, the forward envelope (the speed reachable from the window's
fixed start, capped by the node limit), which never changes once computed, and the planned
entry speed ``entry = min(fw, g(next entry, length))`` (g the monotone reach). Appending a
block only *raises* entries (the window's end moves away), so the backward pass walks from the
newest block and stops at the first entry that does not change: after a block or two at
full speed, after the whole braking chain (a few to a few tens of blocks) on short chords at
low speed. When a block leaves the window the next block's entry is committed; if that
lowers a forward envelope the change is propagated forward until it stops mattering. Both
passes run compiled, on the window's speeds kept in one array (`twin.controller.window`;
its plain Python passes are the reference the tests hold it to, bit for bit). A block leaves
the window when the window holds ``lookahead`` blocks, or as soon as twice the contour
braking distance from the top feed lies behind it (its speeds can no longer change): the
window is as long as the braking distance needs, however short the blocks, and
``lookahead`` bounds its memory.

Blocks therefore come out identical for any window that covers the braking distance (the
backward pass from the window's end saturates before it reaches the block). With runs,
``lookahead`` counts runs.

Decisions
---------
* The machine starts at rest; nodes next to a rapid (G0) are exact stops (seed 003: G0
  brakes at block end), and so are Dwell, Event and ProgramEnd items: they flush the window
  and pass through in order. Nothing after a ProgramEnd is read.
* A program's path control (``PathControl``) is no stop: G61 and G61.1 turn corner
  rounding off and ``G64 P`` sets its tolerance (the blender applies them), and under G61.1
  every block ends at rest (exact stop).
* Contour ``max_velocity`` limits feed moves; rapids are limited by ``rapid_velocity`` and
  the per-axis limits only.
* The rules for a block and a node (the caps above, the runs) are
  `twin.controller.block_rules`; segment caps (per-axis projections, centripetal
  acceleration and jerk on curves) are computed by `twin.controller.segment_limits`.
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
from typing import Any

from twin.config import AxisConfig, ControllerSettings
from twin.controller.blend import BlendedBlock, Blender
from twin.controller.block_rules import (
    APART,
    JOINS,
    TOO_LONG,
    BlockRules,
    WindowBlock,
    absorb,
    close_run,
    open_run,
)
from twin.controller.blocks import (
    MotionBlock,
    PlannedBlock,
    RunMove,
    segment_of,
    segments_from_program,
)
from twin.controller.corner import CornerModel, SeedCornerModel
from twin.controller.gcode.items import Dwell, Move, PathControl, ProgramEnd
from twin.controller.loop_defaults import default_corner_model
from twin.controller.profiles import Limits, min_distance
from twin.controller.profiles.laws import check_law
from twin.controller.stop_zones import StopZones
from twin.controller.window import Window
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
        Largest window (blocks), ≥ 1; a block leaves earlier once the braking distance
        lies behind it. 1 means stop at every node.
    mode : {"lookahead", "stop"}
        ``"stop"`` plans every node at rest (the classic controller, for comparison).
    corner_model : CornerModel, optional
        Node speed limit from the corner angle at a kink; default ``SeedCornerModel()``
        (``from_settings`` gives the machine's, as the controller does).
    period : float, optional
        Controller period T (s): a kink is passed no faster than a velocity step the axes
        take in one period (module doc). None: that rule is off (a bare planner).
    blend : float
        Share of ``tolerance`` that the rounding of kinks may take (0 … 1; 0: no blending,
        the kinks stay); the rest is the servo's. Look-ahead mode only.
    curve_acceleration : float
        A further cap of the centripetal acceleration on curves (m/s²): what input shapers
        allow (``twin.controller.shaped_corner.curve_acceleration``); default none.
    curve_quartic : float
        The cap on curves that the shapers' fourth-order error sets once the smoothing
        compensation removes the second-order one (``SegmentLimits``); 0: none.
    curve_step : float
        The largest step of the normal acceleration v²·|Δκ| a node between feed moves may
        have (m/s²): with the smoothing compensation the shapers' transient where the
        curvature jumps (``twin.controller.compensation.curve_step_acceleration``); default
        none.
    stop_dwell : float
        Time the reference stands still at an exact stop of the look-ahead mode before the
        next move (s): before a machine function (an ``Event``: M3/M5, tool on/off) and
        where a rapid meets another move. With input shapers the controller sets their
        duration: the shaped reference then arrives at the stop before the next move
        leaves it, instead of mixing the two directions (a cut corner at the pierce point).
        Default 0: none.
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
                 min_feed: float = 1e-6, max_program_time: float = 86400.0,
                 period: float | None = None, blend: float = 0.5,
                 curve_acceleration: float = math.inf, curve_quartic: float = 0.0,
                 curve_step: float = math.inf, stop_dwell: float = 0.0):
        check_law(law)
        if not (math.isfinite(stop_dwell) and stop_dwell >= 0.0):
            raise ConfigError("stop_dwell", f"must be finite and >= 0 (s), got {stop_dwell!r}")
        self.stop_dwell = float(stop_dwell)
        if mode not in MODES:
            raise ConfigError("mode", f"must be one of {MODES}, got {mode!r}")
        if isinstance(lookahead, bool) or not isinstance(lookahead, int) or lookahead < 1:
            raise ConfigError("lookahead", f"must be an integer >= 1, got {lookahead!r}")
        if len(axis_limits) != 2:
            raise ConfigError("axis_limits", f"need 2 (x, y), got {len(axis_limits)}")
        for name, value in (("rapid_velocity", rapid_velocity), ("tolerance", tolerance),
                            ("min_feed", min_feed), ("max_program_time", max_program_time),
                            ("period", 1.0 if period is None else period)):
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(name, f"must be finite and > 0, got {value!r}")
        if not (0.0 <= blend <= 1.0):
            raise ConfigError("blend", f"must lie in [0, 1], got {blend!r}")
        self.limits = limits
        self.axis_limits = tuple(axis_limits)
        self.rapid_velocity = float(rapid_velocity)
        self.tolerance = float(tolerance)
        self.law = law
        self._window = Window                # the speed passes (PythonWindow: reference)
        self.lookahead = lookahead
        self.mode = mode
        self.corner_model: CornerModel = corner_model or SeedCornerModel()
        self.work_zone = work_zone
        self.period = None if period is None else float(period)
        self.blend = float(blend)
        # rapids run between exact stops: the feed moves' top speed sets the view
        self._view = 2.0 * min_distance(law, limits.max_velocity, 0.0, limits)
        self._rules = BlockRules(limits, self.axis_limits, rapid_velocity=self.rapid_velocity,
                                 tolerance=self.tolerance, corner_model=self.corner_model,
                                 period=self.period, jerk=law != "trapezoid", view=self._view,
                                 curve_acceleration=curve_acceleration,
                                 curve_quartic=curve_quartic, curve_step=curve_step)
        self.min_feed = float(min_feed)
        self.max_program_time = float(max_program_time)
        self._time_bound = 0.0
        self._zones: StopZones | None = None

    @classmethod
    def from_settings(cls, settings: ControllerSettings, axes: Mapping[str, AxisConfig],
                      **options: Any) -> Planner:
        """A planner from the machine's controller settings and axes.

        Keyword options override: ``law`` (default ``settings.profile``), ``mode``
        (``settings.planner``), ``lookahead``, ``corner_model`` (default the machine's,
        `twin.controller.loop_defaults.default_corner_model`, as the controller's),
        ``work_zone`` (default the axes' travel inside the limit switches when
        ``settings.soft_limits``, else None; pass None to disable), ``tolerance``,
        ``period``, ``blend``.
        """
        if options.get("corner_model") is None:
            options["corner_model"] = default_corner_model(settings, axes)
        options.setdefault("law", settings.profile)
        options.setdefault("mode", settings.planner)
        options.setdefault("lookahead", settings.lookahead)
        options.setdefault("tolerance", settings.contour_tolerance)
        options.setdefault("min_feed", settings.min_feed)
        options.setdefault("max_program_time", settings.max_program_time)
        options.setdefault("period", settings.period)
        options.setdefault("blend", settings.corner_blend)
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
        self._blocks: deque[WindowBlock] = deque()    # the window (its speeds: _speeds)
        self._speeds = self._window(self.law, self.lookahead)
        stream: Iterator[Any] = self._checked(items)
        if self.mode == "lookahead" and self.blend > 0.0:
            stream = Blender(self.blend * self.tolerance).blend(stream)
        runs = self.mode == "lookahead" and self.law != "trapezoid" and self.lookahead > 1
        error: TwinError | None = None
        rules = self._rules
        rules.count = 0
        block_of, joins_of = rules.block, rules.joins
        follow = rules.follow if rules.slivers else None
        last: WindowBlock | None = None      # the feed block before, for `follow`
        self._time_bound = 0.0
        self._length = 0.0
        # the blocks that leave the window (_pop) gather here and are yielded after each
        # step: plain calls, no generator per block
        out: list[PlannedBlock] = []
        self._out = out
        append, flush, end_run = self._append, self._flush, self._end_run
        self._zones = None if self.mode != "lookahead" or self.lookahead < 2 else StopZones(
            rules, self.law, 0.5 * self._view, self._push, runs)
        exact_stop = False
        run: WindowBlock | None = None       # the run being grown
        held: WindowBlock | None = None      # a run closed for its length, its successor to come
        rest = False                         # the run starts at a stop
        tail: WindowBlock | None = None      # a short block after the run: a stop next?
        while True:
            if out:
                yield from out
                out.clear()
            try:
                item = next(stream)
            except StopIteration:
                break
            except TwinError as exc:
                error = exc
                break
            if type(item) is BlendedBlock:
                block = block_of(*item)
                after_stop = last is None
                if tail is not None:            # the run ends at a rapid, or goes on
                    if block.rapid:
                        absorb(run, tail)
                    else:
                        end_run(held, run)
                        run, held, rest = open_run(tail), None, False
                    tail = None
                if block.rapid:
                    last = None
                else:
                    if last is not None and follow is not None:
                        follow(last, block)
                    last = block
                if exact_stop:                  # G61.1: every block ends at rest
                    if run is not None:
                        end_run(held, run)
                        run = held = None
                    append(block)
                    flush()
                    continue
            elif type(item) is PathControl:     # G61, G61.1, G64: no stop, nothing to run
                exact_stop = item.mode == "exact_stop"
                continue
            else:
                last = None
                if tail is not None:            # a stop: the short block ends the run
                    absorb(run, tail)
                    tail = None
                if run is not None:
                    end_run(held, run)
                    run = held = None
                flush()
                yield from out
                out.clear()
                yield item
                if isinstance(item, ProgramEnd):
                    break
                continue
            if not runs:
                append(block)
                continue
            joins = joins_of(run, block, rest) if run is not None else APART
            if joins == JOINS:
                absorb(run, block)
                continue
            if joins == APART and run is not None and self._tail(run, block):
                tail = block                    # joins if a stop follows (`_tail`)
                continue
            if joins == TOO_LONG:              # the same curve goes on: hold this part
                if held is not None:
                    append(close_run(held))
                held = run
            elif run is not None:
                end_run(held, run)
                held = None
            run, rest = open_run(block), after_stop
        if tail is not None:
            absorb(run, tail)
        if run is not None:
            end_run(held, run)
        flush()
        yield from out
        out.clear()
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
        for _ in self._checked(items):
            pass

    # ------------------------------------------------------------------ internals
    def _checked(self, items: Iterable[Any]) -> Iterator[Any]:
        """Motion items as checked ``BlendedBlock``s (work zone, minimum feed, program time,
        all on the programmed segment); dwells, events and the program end pass through;
        nothing after the program end is read."""
        zone = self.work_zone
        settle = self.stop_dwell if self.mode == "lookahead" else 0.0
        last: bool | None = None         # the last motion's rapid flag; None: at rest
        for item in _read_ahead(items):
            kind = type(item)
            if kind is Move:                 # segments_from_program, inlined
                seg = segment_of(item)
                if seg is None:
                    continue
                feed, line = item.feed, item.line
            elif kind is MotionBlock:
                seg, feed, line = item.segment, item.feed, item.line
            else:
                if kind is Dwell:
                    self._spend(item.duration, item.line, "its dwell")
                elif settle > 0.0 and last is not None and not isinstance(item, ProgramEnd):
                    yield Dwell(settle, item.line)
                last = None
                yield item
                if isinstance(item, ProgramEnd):
                    return
                continue
            if zone is not None:
                zone.check(seg, line)
            self._account(seg.length, feed, line)
            if settle > 0.0 and last is not None and (last or feed is None):
                yield Dwell(settle, line)
            last = feed is None
            yield BlendedBlock(seg, feed, line)

    def _account(self, length: float, feed: float | None, line: int) -> None:
        """The feed bound, and the block's time at full feed (the rapid speed, or the feed
        capped by the contour limit) against the program's."""
        if feed is not None and not feed >= self.min_feed:
            raise PlanningError(f"line {line}: feed {feed * 60e3:.6g} mm/min is below the "
                                f"machine's minimum {self.min_feed * 60e3:.6g} mm/min "
                                "(controller.min_feed)")
        self._spend(length / self._rules.full_speed(feed), line, "its moves")

    def _spend(self, seconds: float, line: int, what: str) -> None:
        self._time_bound += seconds
        if not self._time_bound <= self.max_program_time:
            raise PlanningError(f"line {line}: the program takes at least "
                                f"{self._time_bound:.6g} s with {what} so far, beyond the "
                                f"machine's {self.max_program_time:g} s "
                                "(controller.max_program_time)")

    def _tail(self, run: WindowBlock, b: WindowBlock) -> bool:
        """Whether ``b``, kept apart from ``run``, would join it if a stop followed: so
        short that its node cannot bind at a stop's end (`BlockRules.slow_node`: a
        contour's last chord after its curve), and no lower in its caps than the run
        (joining lowers nothing of the run's)."""
        return (b.v_nom >= run.v_nom and b.acc >= run.acc and b.jerk >= run.jerk
                and self._rules.slow_node(run, b, b.length))

    def _end_run(self, held: WindowBlock | None, run: WindowBlock) -> None:
        """Append the last run of a curve, and the part of it held before: one run if the
        last is short (so that a change near the curve's end is not cut in two)."""
        if held is not None:
            if run.length < 0.5 * self._view:
                for m in run.members:
                    absorb(held, m)
                self._append(close_run(held))
                return
            self._append(close_run(held))
        self._append(close_run(run))

    def _append(self, b: WindowBlock) -> None:
        """Add ``b`` to the window through the stop zones (`twin.controller.stop_zones`:
        a rapid is a stop before it)."""
        zones = self._zones
        if zones is None:
            self._push(b)
        elif b.rapid:
            zones.stop()
            self._push(b)
        else:
            zones.feed(b)

    def _flush(self) -> None:
        """A stop: the zones before it laid, every block leaves the window."""
        if self._zones is not None:
            self._zones.stop()
        while self._blocks:
            self._pop()

    def _push(self, b: WindowBlock) -> None:
        """Add ``b`` to the window (both passes, `twin.controller.window`); the blocks that
        leave it go to ``_out``."""
        self._length = length = self._length + b.length
        rules, window = self._rules, self._blocks
        n = len(window)
        prev = window[-1] if n else None
        if prev is None or self.mode == "stop" or prev.rapid or b.rapid:
            emax, linked = 0.0, False
        else:
            last = prev.members[-1] if prev.members else prev
            first = b.members[0] if b.members else b
            emax = rules.node_cap(last, first)
            if prev.v_nom < emax:
                emax = prev.v_nom
            if b.v_nom < emax:
                emax = b.v_nom
            linked = True
        # the window's first block leaves once the window holds `lookahead`, or the view
        # lies behind it: the first so found is committed in the same compiled call
        leaves = n + 1 >= self.lookahead or (n > 0 and length - window[0].length >= self._view)
        ends = self._speeds.append(b.length, rules.limits_of(b), emax, linked, leaves)
        window.append(b)
        if leaves:
            self._pop(ends)
            while len(window) >= self.lookahead or (
                    len(window) > 1 and self._length - window[0].length >= self._view):
                self._pop()

    def _pop(self, ends: tuple[float, float] | None = None) -> None:
        """Commit the window's first block (or run), or take its speeds ``ends`` (entry, end)
        as committed; what it plans goes to ``_out``."""
        b = self._blocks.popleft()
        self._length -= b.length
        entry, v_end = ends or self._speeds.commit()
        members = b.members
        if members is None:
            self._out.append(PlannedBlock(b.segment, b.feed, entry, b.v_nom, v_end, self.law,
                                          b.limits, b.line, b.index, b.blend))
            return
        # a run: one move over the members, each block its part of it (the move, and the
        # times and speeds inside it, are made when a block is used: RunMove)
        run = RunMove(self.law, b.length, entry, v_end, b.v_nom, b.limits)
        d0, last = 0.0, len(members) - 1
        out, law, v_nom, limits = self._out, self.law, b.v_nom, b.limits
        for k, m in enumerate(members):
            d1 = b.length if k == last else d0 + m.length
            out.append(PlannedBlock(m.segment, m.feed, entry if k == 0 else None, v_nom,
                                    v_end if k == last else None, law, limits, m.line,
                                    m.index, m.blend, (run, d0, d1)))
            d0 = d1


READ_AHEAD = 64
"""Motion items taken from the program at a time. Reading and planning in turns of 64 keeps
each one's code and data warm in the CPU's caches: streaming a chord program from a file
plans 1.2-1.3x faster than item by item (one item at a time, the reader and the planner
evict each other)."""


def _read_ahead(items: Iterable[Any]) -> Iterator[Any]:
    """``items`` in order, taken ``READ_AHEAD`` at a time; a batch ends at the first item
    that is not a motion block (a dwell, an event, the program end: what follows one is not
    read before the planner has passed it, as item by item), and an error of the source
    comes after the items read before it."""
    source = iter(items)
    batch: list[Any] = []
    take = batch.append
    while True:
        try:
            for _ in range(READ_AHEAD):
                item = next(source)
                take(item)
                kind = type(item)
                if kind is not Move and kind is not MotionBlock:
                    break
        except StopIteration:
            yield from batch
            return
        except Exception:
            yield from batch
            raise
        yield from batch
        batch.clear()
