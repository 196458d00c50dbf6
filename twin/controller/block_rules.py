"""The planner's rules for blocks and nodes (seed 001's technological and accuracy
limits), and the runs of the smooth laws: what ``Planner`` applies to each block before its
window's speed passes (see `twin.controller.planner`'s module doc for the rules' reasons).

``BlockRules.block`` summarises a segment as a ``WindowBlock``: its speed cap (the feed or
the rapid speed within the contour limit and the per-axis and curve caps of
`twin.controller.segment_limits`), its tangential limits, its end tangents and curvatures.
``BlockRules.node_cap`` is the speed limit of a node: both blocks' caps, at a kink the
corner model and the velocity step the axes take in one period (for a law that limits
jerk, the jerk that step shows), where the curvature jumps the step of the normal
acceleration as the samples see it; ``BlockRules.follow`` lets a sliver of line between
two curves carry the curvature across. ``BlockRules.joins`` says whether a block may join a
run; ``open_run``, ``absorb`` and ``close_run`` grow a run and close it into one window
block. ``BlockRules.slow`` caps a block or run below its cap with the tangential limits its
arcs allow there (the stop zones of `twin.controller.stop_zones`).
"""

from __future__ import annotations

import math

from twin.controller.corner import CornerModel
from twin.controller.geometry import Arc, Line, Segment
from twin.controller.profiles import Limits
from twin.controller.segment_limits import SegmentLimits

__all__ = ["APART", "JOINS", "RUN_CAP_SHARE", "RUN_LIMIT_SHARE", "SLIVER_JERK", "STEP_SEEN",
           "STRAIGHT", "TOO_LONG", "BlockRules", "WindowBlock", "absorb", "close_run",
           "open_run", "tangential_limits"]

APART, JOINS, TOO_LONG = 0, 1, 2
"""``BlockRules.joins``: apart, joins the run, or the run is as long as the view."""
RUN_CAP_SHARE = 0.95
"""A block joins a run (which then runs at the lower of their speed caps) only if the time
that costs — the faster part, the block or the run so far, slowed to the lower cap — is at
most 1 − RUN_CAP_SHARE (5 %) of the time of the run with it at the lower cap, or of the
view at the higher. So caps within about 5 % join, and so does a short block, or a short
start of a run, whose cap is further off: a run cut at every scatter of the caps of a
chorded curve would confine its changes of speed to pieces a few chords long."""

_SLACK = 1.0 - RUN_CAP_SHARE

RUN_LIMIT_SHARE = 0.6
"""A block joins a run only if its tangential acceleration and jerk limits agree with the
run's within this share, or the part whose limits the joining lowers (the block, or the run
so far) is short (5 % of the run with it): the run's changes of speed use the lowest of its
members' limits (a tight curve's are low)."""

STEP_SEEN = 1.0
"""The share of a step of acceleration Δa between two samples that the reference passed to
the regulator shows, over Δa/T. The sampled position's third difference shows at most 3/4
of it (its second difference averages the acceleration by a triangle of half-width T, and
one period holds at most 3/4 of that triangle's area), but the regulator's feed-forward
terms take the interpolator's acceleration itself, which steps by the whole Δa in one
period: the drive receives all of it. A curvature step Δκ passed at v is held to
v²·|Δκ|·STEP_SEEN ≤ J·T."""

SLIVER_JERK = 0.1
"""A line after a curve is a sliver (a blend that could not reach the middle of a chord by
a rounding's width) when missing the curve's normal acceleration along it shows in the
sampled reference as a jerk of at most this share of J (`BlockRules.follow`)."""

STRAIGHT = 1e-9
"""A node whose tangent turns by less than this (rad) is straight through: a blend's ends
meet their lines at angles of 1e-16..1e-12 from rounding. Below it neither the corner model
(``δ/(sin θ · f2)``, beyond 1e5 m/s for any δ ≥ 1 µm and f2 ≤ 0.01 s) nor the velocity
step (``A·T/θ``, beyond 1e4 m/s for any A ≥ 0.1 m/s² and T ≥ 0.1 ms) could cap a speed."""


class WindowBlock:
    """A block in the window: its geometry summary and its speeds (mutable, internal).

    A *run* is a ``WindowBlock`` whose ``members`` are consecutive blocks planned as one: its
    length their sum, its caps their lowest (``acc``, ``jerk``: the tangential limits).
    """

    __slots__ = ("acc", "blend", "feed", "from_k", "from_x", "from_y", "index", "jerk", "k0",
                 "k1", "length", "limits", "line", "members", "node", "rapid", "segment", "t0x",
                 "t0y", "t1x", "t1y", "v_nom")


class BlockRules:
    """The rules for blocks and nodes of one planner (see the module doc).

    Parameters
    ----------
    limits, axis_limits : Limits
        Contour and per-axis limits.
    rapid_velocity : float
        Speed of G0 moves (m/s).
    tolerance : float
        Allowed contour error at corners (m), for the corner model.
    corner_model : CornerModel
    period : float or None
        Controller period (s) for the velocity-step rules; None: they are off.
    jerk : bool
        Whether the law limits jerk (curve caps and the curvature-step rule).
    view : float
        Twice the braking distance from the top feed (m): a run is not grown beyond it.
    curve_acceleration, curve_quartic : float
        The caps on curves of input shapers (``SegmentLimits``).
    curve_step : float
        The largest step v²·|Δκ| of the normal acceleration at a node (m/s²): the input
        shapers' transient under the smoothing compensation; default none.

    Attributes
    ----------
    count : int
        Blocks made so far (the next block's index); the planner resets it per plan.
    """

    def __init__(self, limits: Limits, axis_limits: tuple[Limits, Limits], *,
                 rapid_velocity: float, tolerance: float, corner_model: CornerModel,
                 period: float | None, jerk: bool, view: float,
                 curve_acceleration: float = math.inf, curve_quartic: float = 0.0,
                 curve_step: float = math.inf):
        self.limits, self.rapid_velocity, self.tolerance = limits, rapid_velocity, tolerance
        self.corner_model = corner_model
        self._caps = SegmentLimits(limits, axis_limits, jerk=jerk,
                                   curve_acceleration=curve_acceleration,
                                   curve_quartic=curve_quartic)
        # a kink's velocity step per axis and on the contour: v·|Δt̂_k| ≤ A_k·T
        self._step = None if period is None else (
            axis_limits[0].max_acceleration * period, axis_limits[1].max_acceleration * period,
            limits.max_acceleration * period)
        # a node where the curvature jumps (a line meets an arc, a blend of another radius)
        # steps the normal acceleration by v²·|Δκ| within one period: at most J·T for a law
        # that limits jerk
        # for a law that limits jerk, a kink's velocity step Δv shows in the sampled
        # reference's third difference as up to Δv/T²: v·|Δt̂_k| ≤ J_k·T² (an exact stop,
        # nearly: 0.3 mm/s at a right angle on laser_belt; G61 corners, arcs meeting lines)
        self._kink_jerk = None if period is None or not jerk else (
            axis_limits[0].max_jerk * period**2, axis_limits[1].max_jerk * period**2,
            limits.max_jerk * period**2)
        j_total = min(limits.max_jerk, axis_limits[0].max_jerk, axis_limits[1].max_jerk)
        self._jerk_step = None if period is None or not jerk else (
            period * j_total / STEP_SEEN)
        # a sliver: ℓ·√(A·|κ|) ≤ SLIVER_JERK·J·T², written ℓ·√|κ| ≤ SLIVER_JERK·J·T²/√A
        self._sliver = None if self._jerk_step is None else (
            SLIVER_JERK * j_total * period * period / math.sqrt(limits.max_acceleration))
        self.slivers = self._sliver is not None     # whether `follow` can change a block
        self._curve_step = float(curve_step)
        self._view = view
        self._limits_cache: dict[tuple[float, float, float], Limits] = {}
        self._top = limits.max_velocity
        self.count = 0

    def full_speed(self, feed: float | None) -> float:
        """A block's speed before any other cap (m/s): rapid, or the feed within the
        contour limit."""
        top = self._top
        return self.rapid_velocity if feed is None else (top if top < feed else feed)

    def block(self, seg: Segment, feed: float | None, line: int, blend: bool = False,
              index: int | None = None) -> WindowBlock:
        """The window block of ``seg``: its caps, tangential limits, end tangents and
        curvatures; numbered ``count`` (counted), or ``index`` (a part of a block already
        numbered: `twin.controller.stop_zones` splits blocks next to stops)."""
        top = self._top                     # full_speed, inlined (once per block)
        v_cap = self.rapid_velocity if feed is None else (top if top < feed else feed)
        b = WindowBlock()
        b.segment, b.feed, b.line, b.blend = seg, feed, line, blend
        b.rapid = feed is None
        b.length = seg.length
        if index is None:
            b.index = self.count
            self.count += 1
        else:
            b.index = index
        if type(seg) is Line:
            ux, uy = seg._ux, seg._uy      # float fast path (same package)
            b.t0x = b.t1x = ux
            b.t0y = b.t1y = uy
            b.k0 = b.k1 = 0.0
            v_nom, acc, jerk = self._caps.line_caps(abs(ux), abs(uy), v_cap)
        else:
            if type(seg) is Arc:
                b.t0x, b.t0y, b.t1x, b.t1y = seg._ends_t   # end_tangents (same package)
                b.k0 = b.k1 = seg._k
            else:
                _, _, b.t0x, b.t0y, b.k0, _ = seg.frame(0.0)
                _, _, b.t1x, b.t1y, b.k1, _ = seg.frame(seg.length)
            v_nom, acc, jerk = self._caps.curve_caps(seg, v_cap, blend)
        b.v_nom, b.acc, b.jerk = v_nom, acc, jerk
        b.limits = None                     # made when needed (`limits_of`)
        b.members = None
        b.from_x = math.nan                 # no node limit kept yet (`node_cap`)
        return b

    def limits_of(self, b: WindowBlock) -> Limits:
        """``b``'s tangential limits (``b.limits``), made on first use: a block that joins
        a run never needs its own. Lines of one direction and feed share theirs."""
        lim = b.limits
        if lim is not None:
            return lim
        if type(b.segment) is not Line:     # a curve's caps are its own: no reuse
            lim = b.limits = tangential_limits(b.v_nom, b.acc, b.jerk)
            return lim
        key = (b.v_nom, b.acc, b.jerk)
        lim = self._limits_cache.get(key)
        if lim is None:
            if len(self._limits_cache) > 256:
                self._limits_cache.clear()
            lim = self._limits_cache[key] = tangential_limits(*key)
        b.limits = lim
        return lim

    def curve_limits(self, seg: Arc, v: float) -> tuple[float, float]:
        """Tangential acceleration (m/s²) and jerk (m/s³) of the arc ``seg`` at speeds up
        to ``v`` (m/s; within its caps): `SegmentLimits.tangential`, as its caps give them
        at its cap."""
        return self._caps.tangential(v, 1.0 / seg.radius)

    def slow(self, b: WindowBlock, v: float) -> None:
        """Cap ``b`` (a block or a run) at ``v`` (m/s) and raise its tangential limits to
        what its arcs allow up to that speed (a curve's limits are computed at its cap:
        below it the centripetal acceleration and the curvature's jerk leave more of the
        budgets to the tangent). Nothing changes for ``v ≥ b.v_nom``, for a block without
        an arc (a line's limits do not depend on the speed), or with a curve other than an
        arc (a spline's caps are sampled: left as they are)."""
        if not v < b.v_nom:
            return
        acc = jerk = math.inf
        arc = False
        for m in b.members or (b,):
            seg = m.segment
            if type(seg) is Arc:
                a, j = self.curve_limits(seg, v if v < m.v_nom else m.v_nom)
                arc = True
            elif type(seg) is Line:
                a, j = m.acc, m.jerk
            else:
                return
            if a < acc:
                acc = a
            if j < jerk:
                jerk = j
        if arc:
            b.v_nom, b.acc, b.jerk = v, acc, jerk
            b.limits = tangential_limits(v, acc, jerk)

    def follow(self, prev: WindowBlock, b: WindowBlock) -> None:
        """Note that ``b`` follows ``prev`` (consecutive feed blocks): a sliver of line after
        a curve takes the curve's end curvature for the curvature-step rule, so the step is
        counted once, at the sliver's end, as large as the curves on both sides make it.

        Passing a line of length ℓ after a curve κ at speed v drops the normal acceleration
        v²κ for ℓ/v: the sampled reference shows a jerk of about v·κ·ℓ/T² there, at most
        √(A·|κ|)·ℓ/T² at the curve's centripetal limit. The line is a sliver when that is
        at most ``SLIVER_JERK``·J. Off with the curvature-step rule (no period, no jerk)."""
        k = prev.k1
        if (self._sliver is not None and b.k0 == 0.0 and b.k1 == 0.0 and k != 0.0
                and b.length * math.sqrt(abs(k)) <= self._sliver):
            b.k0 = b.k1 = k

    def node_cap(self, prev: WindowBlock, b: WindowBlock) -> float:
        """The speed limit of the node from ``prev`` to ``b`` (m/s): both segments' caps,
        and at a kink the corner model and the velocity step, where the curvature jumps the
        step of the normal acceleration (module doc); ``prev`` and ``b`` are blocks, not
        runs. A node is asked for up to three times: its own part (`node_limit`) is kept on
        ``b`` (``b.node``) with the end of ``prev`` it was computed for (``b.from_*``)."""
        emax = prev.v_nom if prev.v_nom < b.v_nom else b.v_nom
        if b.from_x != prev.t1x or b.from_y != prev.t1y or b.from_k != prev.k1:
            b.from_x, b.from_y, b.from_k = prev.t1x, prev.t1y, prev.k1
            b.node = self.node_limit(prev, b)
        node = b.node
        return node if node < emax else emax

    def node_limit(self, prev: WindowBlock, b: WindowBlock) -> float:
        """The node's limit from its geometry alone (m/s; inf where nothing limits it): the
        corner model and the velocity step at a kink, the step of the normal acceleration
        where the curvature jumps. Blocks' ends are fixed once made (`follow` sets a
        sliver's curvature before any node of it is asked for)."""
        emax = math.inf
        cross = prev.t1x * b.t0y - prev.t1y * b.t0x
        dot = prev.t1x * b.t0x + prev.t1y * b.t0y
        angle = math.atan2(abs(cross), dot)
        if angle > STRAIGHT:
            corner = self.corner_model.max_node_speed(angle, self.tolerance)
            if corner < emax:
                emax = corner
            if self._step is not None:
                step = step_speed(self._step, b.t0x - prev.t1x, b.t0y - prev.t1y)
                if step < emax:
                    emax = step
            if self._kink_jerk is not None:         # v·|Δt̂| ≤ J·T²
                step = step_speed(self._kink_jerk, b.t0x - prev.t1x, b.t0y - prev.t1y)
                if step < emax:
                    emax = step
        dk = abs(b.k0 - prev.k1)
        if dk > 0.0 and self._jerk_step is not None:    # v²·|Δκ|·STEP_SEEN ≤ J·T
            jump = math.sqrt(self._jerk_step / dk)
            if jump < emax:
                emax = jump
        if dk > 0.0 and self._curve_step < math.inf:      # v²·|Δκ| ≤ the shapers' step
            jump = math.sqrt(self._curve_step / dk)
            if jump < emax:
                emax = jump
        return emax

    def joins(self, run: WindowBlock, b: WindowBlock, rest: bool = False) -> int:
        """Whether ``b`` may join ``run`` (one speed change across them): both feed moves,
        a node that limits nothing, caps within ``RUN_CAP_SHARE`` (``JOINS``); but not
        once the run is as long as the view (``TOO_LONG``); else ``APART``. ``rest``: the
        run starts at a stop; while it is so short that the node cannot bind
        (`slow_node`), neither the node nor the run's higher limits keep ``b`` apart."""
        if b.rapid or run.rapid:
            return APART
        cap, v, length = run.v_nom, b.v_nom, run.length
        if v < cap:                     # the lower cap slows the run so far
            lo, hi, slowed = v, cap, length
        else:                           # or the block
            lo, hi, slowed = cap, v, b.length
        both = length + b.length
        time, view = both / lo, self._view / hi
        if slowed * (1.0 / lo - 1.0 / hi) > _SLACK * (view if view > time else time):
            return APART
        start = rest and self.slow_node(run, b, length)
        share, short = RUN_LIMIT_SHARE, _SLACK * both
        if ((b.acc < share * run.acc or b.jerk < share * run.jerk) and length > short
                and not start):
            return APART                # the run's changes would be slowed
        if (b.acc * share > run.acc or b.jerk * share > run.jerk) and b.length > short:
            return APART                # the block's would
        if not start and self.node_cap(run.members[-1], b) < lo:
            return APART
        return TOO_LONG if length >= self._view else JOINS

    def slow_node(self, run: WindowBlock, b: WindowBlock, length: float) -> bool:
        """Whether the node from ``run`` to ``b`` cannot bind because it lies ``length``
        (m) from a stop: a profile that starts or ends at rest passes it at most at
        √(2·A·length) (A the contour acceleration, above every block's tangential limit),
        and the node's cap is no lower (a curvature step where a contour's first or last
        chord meets its curve: a separate run there would end its speed change at the
        node, as a G2/G3 contour's does not)."""
        if b.rapid or run.rapid:
            return False
        last = run.members[-1] if run.members else run
        cap = self.node_cap(last, b)
        return 2.0 * self.limits.max_acceleration * length <= cap * cap


def step_speed(step: tuple[float, float, float], dx: float, dy: float) -> float:
    """Fastest speed at a kink whose tangent changes by (dx, dy): the velocity step of each
    axis, and of the contour, at most its acceleration limit times the period (m/s)."""
    sx, sy, sc = step
    v = sc / math.sqrt(dx * dx + dy * dy)
    if abs(dx) * v > sx:
        v = sx / abs(dx)
    if abs(dy) * v > sy:
        v = sy / abs(dy)
    return v


def open_run(b: WindowBlock) -> WindowBlock:
    """A run of one block, to be grown by `absorb`."""
    run = WindowBlock()
    run.acc, run.feed, run.index, run.jerk, run.k0, run.k1 = b.acc, b.feed, b.index, b.jerk, \
        b.k0, b.k1
    run.length, run.line, run.rapid, run.segment, run.blend, run.limits = b.length, b.line, \
        b.rapid, b.segment, b.blend, b.limits
    run.t0x, run.t0y, run.t1x, run.t1y, run.v_nom = b.t0x, b.t0y, b.t1x, b.t1y, b.v_nom
    run.members = [b]
    return run


def absorb(run: WindowBlock, b: WindowBlock) -> None:
    run.members.append(b)
    run.length += b.length
    run.t1x, run.t1y, run.k1 = b.t1x, b.t1y, b.k1
    if b.v_nom < run.v_nom:
        run.v_nom = b.v_nom
    if b.acc < run.acc:
        run.acc = b.acc
    if b.jerk < run.jerk:
        run.jerk = b.jerk


def close_run(run: WindowBlock) -> WindowBlock:
    """The run as the window's block: its only member itself, or the run with its limits."""
    if len(run.members) == 1:
        return run.members[0]
    run.limits = tangential_limits(run.v_nom, run.acc, run.jerk)
    run.segment = None
    return run


def tangential_limits(v: float, a: float, j: float) -> Limits:
    """A block's tangential limits; checked where they could be wrong (a non-finite or
    non-positive cap from a degenerate segment), else built without the checks."""
    if 0.0 < v < math.inf and 0.0 < a < math.inf and 0.0 < j < math.inf:
        return Limits.trusted(v, a, j)
    return Limits(v, a, j)
