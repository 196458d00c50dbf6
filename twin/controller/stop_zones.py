"""Stop zones: a curve next to a stop gets the tangential limits its reachable speed allows.

A curve's tangential limits (`twin.controller.segment_limits`) are computed at its speed
cap V: there the centripetal acceleration v²κ and the curvature's jerk (v³κ², 3·v·a_t·κ)
take most of the budgets. Where a contour starts from rest, or ends at a stop, the speed is
far below V and those shares are small: a G2/G3 arc (or a run of blends) that kept the
limits of V for its whole length accelerated out of a stop more slowly than a chorded copy
of it whose first chord, a line, accelerates at the line's limits (issue 30: a circle of
r = 0.5 mm took up to 17 % longer as G3 than as chords within 0.02 mm).

Design: levels of speed by distance from the stop
-------------------------------------------------
Next to each stop (the start of a contour from rest, its end before a stop: a rapid, a
dwell, an event, the program end, every block under G61.1) the curve there is cut into at
most two zones ``[D_(k−1), D_k]`` with speed caps ``v_1 < v_2 < V`` before the rest of it.
The blocks in zone k are capped at ``v_k`` and take the tangential limits their arcs allow
up to ``v_k`` (`BlockRules.slow`); a block that straddles a zone's border is split there
(an arc at the exact distance, both parts keeping the block's number; a run between its
members, at the border nearer the distance, or inside the arc member that holds it; a
line, whose limits do not depend on the speed, is never capped or split). The caps are
constraints the look-ahead holds like any other, and the jerk and acceleration bounds of
`segment_limits` hold at every speed up to a block's cap with the limits computed at that
cap: they hold in every zone.

Zone k is as long as the look-ahead needs to reach ``v_k`` from ``v_(k−1)`` at the limits
of ``v_k`` (`zone`: its monotone reach, the longest change to v_k from any speed in
between), so the profile reaches each cap at its zone's end. The levels are chosen per
stop with the law's closed forms (`choose_levels`): among no zone, one level ``f·V`` and
(the trapezoid) two levels (f from ``FRACTIONS``), the one whose changes from the curve's
entry speed to V lose the least time against cruising at V over the same path,
``Σ t_k − (Σ d_k)/V``, with the limits of the curve of largest curvature within ``reach``
of the stop (the lowest). For a law that ends every change at zero acceleration a zone
border costs a pause of it; the choice weighs that (on laser_belt's circles of
r = 0.5-10 mm the smooth laws take one level at 0.6-0.9 V or none, the trapezoid two at
0.5 and 0.8 V). A choice must fit: the
zones within ``reach`` (half the look-ahead view, the braking distance from the top feed),
and the zones, the change on to V and the change back to the cap of the node that ends
the curve on its far side (a node that binds below 0.95 V, ``RUN_CAP_SHARE``; else at most
half the contour) within the curve.

Where the curve does not start at the stop
------------------------------------------
A contour written as chords starts with a half chord, a line, whose node into the curve
steps the curvature (`BlockRules.node_cap`). For the smooth laws those lines join the
first zone's run where the node cannot bind there: the run from rest reaches at most
``max_end_speed`` of its limits over the lines' length, and that must be within the node's
cap (the rule of `BlockRules.slow_node` with the zone's limits); the circle written as
chords then starts as its G3 arc does. Otherwise (the trapezoid, or a node that would
bind) the zones start at the curve, from the speed the node and the lines allow
(``v_entry``). A curve that begins further than ``reach`` from the stop gets no zone.

Streaming: the blocks pass through a buffer that holds the path within ``reach`` of the
newest block (so the end zone can still be laid when a stop comes) and, after a stop, the
first ``reach`` of the contour (the start zone is laid once it is in); memory stays bounded
by ``reach`` over the shortest block. Splines (curves other than arcs) get no zone.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

from twin.controller.block_rules import (
    RUN_CAP_SHARE,
    BlockRules,
    WindowBlock,
    absorb,
    close_run,
    open_run,
)
from twin.controller.geometry import TAU, Arc, Line
from twin.controller.profiles import Limits
from twin.controller.profiles.laws import change_time, max_end_speed, min_distance

__all__ = ["FRACTIONS", "StopZones", "choose_levels", "split_arc", "split_block", "zone"]

FRACTIONS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
"""Candidate zone caps as shares of the curve's cap V."""

_EPS = 1e-9
"""Splits nearer than this to a block's end (m) are not made."""


def zone(law: str, u: float, w: float, limits: Limits) -> tuple[float, float]:
    """(time (s), length (m)) of a zone entered at ``u`` whose cap ``w`` the look-ahead
    reaches at its end.

    Its reach from u is the monotone envelope of `twin.controller.reach` (the least end
    speed over any start at or above u), so the zone is as long as the longest change to w
    from a speed x in [u, w), and the profile cruises at w over what that adds to the
    change from u. The change from x covers ``(x + w)/2 · T(w − x)``: with Δ = w − x it
    grows with Δ where the acceleration limit binds (the trapezoid's and the shape laws'
    ``k_a·Δ/A``), peaks at Δ = 2w/3 where the jerk limit does (``T ∝ √Δ``) and, for the
    S-curve's ``Δ/A + A/J``, at Δ = w − A²/(2J): those three Δ (within (0, w − u]) hold
    the longest.
    """
    t = change_time(law, w - u, limits)
    d = 0.5 * (u + w) * t
    if law == "trapezoid":                  # monotone: the change from u is the longest
        return t, d
    longest = d
    a, j = limits.max_acceleration, limits.max_jerk
    for dv in (2.0 * w / 3.0, w - a * a / (2.0 * j)):
        if 0.0 < dv < w - u:
            longest = max(longest, (w - 0.5 * dv) * change_time(law, dv, limits))
    return t + (longest - d) / w, longest


def choose_levels(law: str, v_cap: float, limits_at: Callable[[float], Limits], reach: float,
                  room: float, v_entry: float = 0.0, v_exit: float | None = None
                  ) -> list[tuple[float, float]]:
    """The zones next to a stop, ``[(D_k, v_k)]`` with D_k the zone's far border from where
    the curve is entered (m) and v_k its speed cap (m/s), increasing; empty when none saves
    time. Two levels for the trapezoid, whose zone borders cost nothing; one for the laws
    that end every change at zero acceleration (a second border is a second pause of it:
    on the bench's programs, its circles and the small lettering, two levels never won for
    them, 0 of 420 stops).

    Parameters
    ----------
    law : str
        Acceleration law.
    v_cap : float
        The curve's speed cap V (m/s).
    limits_at : callable
        Tangential limits of the curve at speeds up to v (``Limits``).
    reach : float
        Longest the zones may reach (m).
    room : float
        How long the curve is (m): the zones, the change from the last cap to V and the
        change from V to ``v_exit`` must fit in it.
    v_entry : float
        Fastest the curve is entered from the stop's side (m/s): 0 where it starts at the
        stop, else the cap of the node after the lines between (a change ends there).
    v_exit : float, optional
        The cap of the node that ends the curve on its other side (m/s); None: V.
    """
    if not v_cap > v_entry:
        return []
    lim_cap = limits_at(v_cap)
    if v_exit is not None and v_exit < v_cap:
        room -= min_distance(law, v_exit, v_cap, lim_cap)
    t0 = change_time(law, v_cap - v_entry, lim_cap)
    best, levels = t0 - 0.5 * (v_entry + v_cap) * t0 / v_cap, []    # no zone
    caps = [f * v_cap for f in FRACTIONS if f * v_cap > v_entry]
    lims = [limits_at(v) for v in caps]
    rest = []                                 # the change from each cap on to V
    for v in caps:
        t = change_time(law, v_cap - v, lim_cap)
        rest.append((t, 0.5 * (v + v_cap) * t))
    two = law == "trapezoid"
    for i, v1 in enumerate(caps):
        t1, d1 = zone(law, v_entry, v1, lims[i])
        if d1 > reach:
            break
        t2, d2 = rest[i]
        lost = t1 + t2 - (d1 + d2) / v_cap
        if lost < best and d1 + d2 <= room:
            best, levels = lost, [(d1, v1)]
        for k in range(i + 1, len(caps) if two else 0):
            v2 = caps[k]
            t12, d12 = zone(law, v1, v2, lims[k])
            t12, d12 = t1 + t12, d1 + d12
            if d12 > reach:
                break
            t3, d3 = rest[k]
            lost = t12 + t3 - (d12 + d3) / v_cap
            if lost < best and d12 + d3 <= room:
                best, levels = lost, [(d1, v1), (d12, v2)]
    return levels


def split_arc(arc: Arc, s: float) -> tuple[Arc, Arc] | None:
    """The arc cut ``s`` (m) from its start into two arcs of its circle; None where the
    cut would be degenerate (within ``_EPS`` of an end, or of a whole turn)."""
    if not _EPS < s < arc.length - _EPS:
        return None
    span = abs(arc.sweep)
    first, second = s / arc.radius, span - s / arc.radius
    turns1, rem1 = divmod(first, TAU)
    turns2, rem2 = divmod(second, TAU)
    if min(rem1, TAU - rem1, rem2, TAU - rem2) * arc.radius <= _EPS:
        return None
    x, y, *_ = arc.frame(s)
    cx, cy, x0, y0, x1, y1 = arc._xy      # start, end, centre as floats (same package)
    a = Arc((x0, y0), (x, y), (cx, cy), ccw=arc.ccw, turns=int(turns1), tol=1e-9)
    b = Arc((x, y), (x1, y1), (cx, cy), ccw=arc.ccw, turns=int(turns2), tol=1e-9)
    if abs(a.length + b.length - arc.length) > 1e-9:
        return None
    return a, b


def _as_block(members: list[WindowBlock]) -> WindowBlock:
    run = open_run(members[0])
    for m in members[1:]:
        absorb(run, m)
    return close_run(run)


def split_block(rules: BlockRules, b: WindowBlock, s: float
                ) -> tuple[WindowBlock, WindowBlock] | None:
    """``b`` (a block or a run) cut about ``s`` (m) from its start: an arc exactly there
    (both parts keep its number), a run between its members at the border nearer ``s``
    (or in the arc member that holds ``s``); None where no cut is possible (a line, a
    spline, a run whose nearer border is one of its ends)."""
    if b.members is None:
        seg = b.segment
        if type(seg) is not Arc:
            return None
        parts = split_arc(seg, s)
        if parts is None:
            return None
        return tuple(rules.block(p, b.feed, b.line, b.blend, index=b.index)  # type: ignore
                     for p in parts)
    members = b.members
    i, c0 = 0, 0.0
    while c0 + members[i].length < s:       # the member that holds s
        c0 += members[i].length
        i += 1
        if i == len(members):
            return None
    m = members[i]
    c1 = c0 + m.length
    front, back = members[:i], members[i + 1:]
    parts = split_block(rules, m, s - c0) if type(m.segment) is Arc else None
    if parts is not None:
        front, back = [*front, parts[0]], [parts[1], *back]
    elif s - c0 < c1 - s:
        back = [m, *back]
    else:
        front = [*front, m]
    if not front or not back:
        return None
    return _as_block(front), _as_block(back)


class StopZones:
    """Lays the stop zones (module doc) on a stream of window blocks.

    Parameters
    ----------
    rules : BlockRules
        The planner's rules (caps at a speed, block parts).
    law : str
        Acceleration law.
    reach : float
        Longest a zone reaches from its stop (m); the buffer holds this much path.
    emit : callable
        Takes each block (zoned) in order, as it may enter the window.
    """

    def __init__(self, rules: BlockRules, law: str, reach: float,
                 emit: Callable[[WindowBlock], None], runs: bool = True):
        self._rules, self._law, self._reach, self._emit = rules, law, reach, emit
        self._runs = runs
        self._buf: deque[WindowBlock] = deque()
        self._length = 0.0              # of the buffer
        self._fresh = True              # the buffer starts at a stop, its zone not laid yet
        self._contour = 0.0             # path since the last stop
        self._head = 0                  # blocks at the buffer's front in the start zone

    def feed(self, b: WindowBlock) -> None:
        """A feed block (or run) follows the ones before without a stop."""
        buf = self._buf
        buf.append(b)
        self._length = length = self._length + b.length
        self._contour += b.length
        if self._fresh:
            if length < self._reach:
                return
            self._lay(start=True, room=math.inf)
            self._fresh = False
        reach = self._reach
        while length - buf[0].length >= reach and len(buf) > 1:
            x = buf.popleft()
            self._length = length = length - x.length
            if self._head:
                self._head -= 1
            self._emit(x)

    def stop(self) -> None:
        """A stop follows: lay the zones and emit everything held."""
        buf = self._buf
        if buf:
            room = 0.5 * self._contour
            if self._fresh:
                self._lay(start=True, room=room)
            self._lay(start=False, room=room)
            emit = self._emit
            while buf:
                emit(buf.popleft())
        self._length = self._contour = 0.0
        self._fresh, self._head = True, 0

    # ------------------------------------------------------------------ internals
    def _lay(self, start: bool, room: float) -> None:
        """The zones at the buffer's start (after a stop) or end (before one: what the
        start zone laid is left as it is)."""
        held = list(self._buf)
        front = [] if start else held[:self._head]
        seq = held if start else held[len(front):][::-1]
        reach = self._reach
        arc, v_cap, line_acc, line_jerk = None, math.inf, math.inf, math.inf
        s = 0.0
        for b in seq:                         # the curve next to the stop
            if s >= reach:
                break
            for m in b.members or (b,):
                seg = m.segment
                if type(seg) is Arc:
                    if arc is None or seg.radius < arc.radius:
                        arc = seg
                    v_cap = min(v_cap, b.v_nom)
                elif type(seg) is Line:
                    line_acc, line_jerk = min(line_acc, m.acc), min(line_jerk, m.jerk)
                else:
                    return                    # a spline next to the stop: no zone
            s += b.length
        if arc is None:
            return
        rules = self._rules
        entry, entry_cap = 0.0, 0.0           # the lines before the curve, its entry
        i = next(k for k, b in enumerate(seq)
                 if any(type(m.segment) is Arc for m in b.members or (b,)))
        lead = sum(b.length for b in seq[:i])
        if i > 0:
            entry_cap = _node_cap(rules, seq[i - 1], seq[i], start)
            entry = min(entry_cap, math.sqrt(2.0 * rules.limits.max_acceleration * lead))

        def limits_at(v: float) -> Limits:
            acc, jerk = rules.curve_limits(arc, v)
            return Limits.trusted(v, min(acc, line_acc), min(jerk, line_jerk))

        stretch = seq[i].length     # the curve up to a node that binds below V (if held)
        v_exit = None
        for k in range(i + 1, len(seq)):
            exit_cap = min(seq[k].v_nom, _node_cap(rules, seq[k - 1], seq[k], start))
            if exit_cap < RUN_CAP_SHARE * v_cap:
                room, v_exit = min(room, lead + stretch), exit_cap
                break
            stretch += seq[k].length
        law = self._law
        levels = choose_levels(law, v_cap, limits_at, reach, room, 0.0, v_exit) if \
            lead > 0.0 and self._runs else []
        merge = bool(levels) and levels[0][0] > lead + _EPS and max_end_speed(
            law, 0.0, lead, limits_at(levels[0][1])) <= entry_cap
        if not merge:                         # the curve's zones from its entry
            levels = [(lead + d, v) for d, v in choose_levels(
                law, v_cap, limits_at, reach - lead, room - lead, entry, v_exit)]
        if not levels:
            return
        out, zoned = _zoned(rules, seq, levels, start)
        if merge:                             # the lines join the first zone's run
            near_stop = out[:i + 1] if start else out[i::-1]         # in path order
            zone = _as_block([m for b in near_stop for m in (b.members or (b,))])
            rules.slow(zone, levels[0][1])
            if max_end_speed(law, 0.0, lead, rules.limits_of(zone)) <= entry_cap:
                out[:i + 1] = [zone]
                zoned -= i
        if start:
            self._head = zoned
        self._buf.clear()
        self._buf.extend(out if start else front + out[::-1])


def _node_cap(rules: BlockRules, a: WindowBlock, b: WindowBlock, start: bool) -> float:
    """The cap of the node between ``a`` and ``b``, consecutive in ``seq``'s order (path
    order after a stop, reversed before one)."""
    near, far = (a, b) if start else (b, a)
    near = near.members[-1] if near.members else near
    far = far.members[0] if far.members else far
    return rules.node_cap(near, far)


def _zoned(rules: BlockRules, seq: list[WindowBlock], levels: list[tuple[float, float]],
           start: bool) -> tuple[list[WindowBlock], int]:
    """``seq`` (from the stop outwards) with its blocks capped at the ``levels``' speeds
    up to their borders, a block straddling a border split there where it can be; and
    how many blocks of it lie in a zone."""
    out: list[WindowBlock] = []
    k, s, zoned = 0, 0.0, 0
    for b in seq:
        inside = False
        while k < len(levels) and s < levels[k][0]:
            border, v = levels[k]
            near = border - s
            if b.length <= near + _EPS:
                rules.slow(b, v)
                inside = True
                break
            parts = split_block(rules, b, near if start else b.length - near)
            if parts is None:
                if near >= 0.5 * b.length:
                    rules.slow(b, v)
                    inside = True
                    break
                k += 1
                continue
            zone, b = parts if start else parts[::-1]
            rules.slow(zone, v)
            out.append(zone)
            s += zone.length
            zoned += 1
            k += 1
        zoned += inside
        out.append(b)
        s += b.length
    return out, zoned
