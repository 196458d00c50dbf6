"""The planner's blocks: what it reads (``MotionBlock``, G-code ``Move``s turned into
segments) and what it yields (``PlannedBlock``: a segment with its planned speeds and its
speed profile, its own move or its part of a run's)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from twin.controller.gcode.items import Move
from twin.controller.geometry import Arc, Line, Segment
from twin.controller.profiles import Limits, Profile, plan_move

__all__ = ["MotionBlock", "PlannedBlock", "RunMove", "segment_of", "segments_from_program"]


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


class PlannedBlock:
    """One block with its planned speeds.

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
        0-based number of the block in the plan (blends included).
    blend : bool
        True for an arc the planner inserted to round a corner (``line`` is then the
        outgoing block's).
    piece : (Profile, float, float) or None
        For a block that shares one speed change with its neighbours (a smooth law over a
        run of short blocks): the run's profile and where this block starts and ends along
        it (m); its own profile is that part, and its speeds are the run's there (computed
        when asked). None: the block's profile is its own move.
    """

    __slots__ = ("_piece", "_times", "_v_end", "_v_start", "blend", "feed", "index", "law",
                 "limits", "line", "segment", "v_nominal")

    def __init__(self, segment: Segment, feed: float | None, v_start: float | None,
                 v_nominal: float, v_end: float | None, law: str, limits: Limits, line: int,
                 index: int, blend: bool = False,
                 piece: tuple[Profile | RunMove, float, float] | None = None):
        self.segment, self.feed, self.v_nominal = segment, feed, v_nominal
        self._v_start, self._v_end = v_start, v_end
        self.law, self.limits, self.line, self.index = law, limits, line, index
        self.blend, self._piece = blend, piece
        self._times: tuple[float, float] | None = None

    @property
    def piece(self) -> tuple[Profile, float, float] | None:
        """The run's profile and this block's part of it (see the class doc); a run's move
        is planned when one of its blocks first asks (``RunMove``)."""
        piece = self._piece
        if piece is not None and type(piece[0]) is RunMove:
            piece = self._piece = (piece[0].profile(), piece[1], piece[2])
        return piece  # type: ignore[return-value]

    def __repr__(self) -> str:
        return (f"PlannedBlock(segment={self.segment!r}, feed={self.feed!r}, "
                f"v_start={self.v_start!r}, v_nominal={self.v_nominal!r}, "
                f"v_end={self.v_end!r}, law={self.law!r}, line={self.line}, "
                f"index={self.index}, blend={self.blend})")

    @property
    def rapid(self) -> bool:
        """True for a G0 block."""
        return self.feed is None

    def _piece_times(self) -> tuple[float, float]:
        if self._times is None:
            run, d0, d1 = self.piece
            self._times = (run.time_at(d0), run.time_at(d1))
        return self._times

    @property
    def v_start(self) -> float:
        """Speed at the start node (m/s)."""
        if self._v_start is None:
            self._v_start = self.piece[0].at(self._piece_times()[0])[1]
        return self._v_start

    @property
    def v_end(self) -> float:
        """Speed at the end node (m/s)."""
        if self._v_end is None:
            run = self.piece[0]
            t1 = self._piece_times()[1]
            self._v_end = run.v_end if t1 >= run.duration else run.at(t1)[1]
        return self._v_end

    def profile(self) -> Profile:
        """The block's speed profile along its segment: ``plan_move`` of its law, or its
        part of the run's profile (``piece``)."""
        if self.piece is not None:
            t0, t1 = self._piece_times()
            return self.piece[0].slice(t0, t1)
        return plan_move(self.law, self.segment.length, v_start=self.v_start,
                         v_end=self.v_end, v_max=self.v_nominal, limits=self.limits)


class RunMove:
    """The one speed change the blocks of a run share (a smooth law over short blocks),
    planned by ``plan_move`` when one of them first asks, as a single block's own profile is
    (``PlannedBlock.profile``): the look-ahead decides the speeds at the nodes, the profile
    between them is made when the block is used."""

    __slots__ = ("_args", "_profile")

    def __init__(self, law: str, distance: float, v_start: float, v_end: float,
                 v_max: float, limits: Limits):
        self._args = (law, distance, v_start, v_end, v_max, limits)
        self._profile: Profile | None = None

    def profile(self) -> Profile:
        if self._profile is None:
            law, distance, v_start, v_end, v_max, limits = self._args
            self._profile = plan_move(law, distance, v_start=v_start, v_end=v_end,
                                      v_max=v_max, limits=limits)
        return self._profile


def segment_of(move: Move) -> Segment | None:
    """The ``Line`` or ``Arc`` of a G-code ``Move``; None for a zero-length line."""
    if move.kind == "arc":
        return Arc(move.start, move.end, move.center, ccw=move.ccw, turns=move.turns)
    if move.start == move.end:
        return None
    return Line.between(move.start, move.end)    # a Move's points are finite float pairs


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
