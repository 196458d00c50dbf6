"""What a G-code program means, in SI: the items the reader yields and the ``Program``.

Every item carries the 1-based source ``line`` it came from. Positions are absolute machine
coordinates in the XY plane (m), feeds are contour speeds (m/s), times are seconds, spindle
speeds rad/s. Nothing here knows about G-code syntax; the reader builds these.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

from twin.controller.gcode.arcs import arc_sweep
from twin.errors import ConfigError

__all__ = [
    "EVENT_KINDS",
    "MOVE_KINDS",
    "Dwell",
    "Event",
    "Item",
    "Move",
    "PathControl",
    "Program",
    "ProgramEnd",
]

MOVE_KINDS = ("rapid", "line", "arc")
"""``Move.kind`` values: G0, G1, and G2/G3."""

EVENT_KINDS = (
    "spindle_cw",      # M3, value None
    "spindle_ccw",     # M4, value None
    "spindle_stop",    # M5, value None
    "spindle_speed",   # S, value: commanded spindle speed (rad/s)
    "tool_select",     # T, value: tool number
    "tool_change",     # M6, value: the selected tool number, None if no T was programmed
    "coolant_mist",    # M7, value None
    "coolant_flood",   # M8, value None
    "coolant_off",     # M9, value None
    "tool_on",         # z = "tool": Z at or below tool_z, or M3/M4 with S > 0; value None
    "tool_off",        # z = "tool": Z above tool_z, M5 or S0; value None
    "pause",           # M0, M1, M60: the program pauses here (the twin runs on); value: code
)
"""``Event.kind`` values, with what ``Event.value`` holds for each."""

_RADIUS_MATCH = 1e-9
"""Largest difference of start and end radius a ``Move`` arc accepts (m, per metre of
coordinate beyond 1 m): the reader builds exact circles, so this only catches arcs assembled
by hand."""


def _point(value: object, field: str) -> tuple[float, float]:
    if type(value) is tuple and len(value) == 2 and type(value[0]) is type(value[1]) is float:
        if math.isfinite(value[0]) and math.isfinite(value[1]):
            return value  # the reader's own points: already right
    try:
        x, y = value  # type: ignore[misc]
        point = (float(x), float(y))
    except (TypeError, ValueError) as exc:
        raise ConfigError(field, f"must be a pair of numbers (m), got {value!r}") from exc
    if not (math.isfinite(point[0]) and math.isfinite(point[1])):
        raise ConfigError(field, f"must be finite, got {point}")
    return point


def _check_line(line: object, field: str) -> None:
    if not isinstance(line, int) or line < 1:
        raise ConfigError(field, f"must be a 1-based line number, got {line!r}")


@dataclass(frozen=True, slots=True)
class Move:
    """One motion block in the XY plane.

    Attributes
    ----------
    kind : str
        ``"rapid"`` (G0), ``"line"`` (G1) or ``"arc"`` (G2/G3).
    start, end : tuple of float
        Start and end point, absolute machine coordinates (m). The reader yields
        ``start == end`` only for a full-circle arc.
    feed : float or None
        Programmed contour feed (m/s); None for a rapid (the machine's rapid speed applies).
    center : tuple of float or None
        Arc centre (m), equidistant from ``start`` and ``end``; None for rapids and lines.
    ccw : bool
        Arcs: True for G3 (counter-clockwise seen from +Z), False for G2.
    turns : int
        Arcs: extra full turns beyond the first pass (G2/G3 ``P`` minus one), default 0.
    line : int
        1-based source line.
    block_number : int or None
        The block's ``N`` word, None without one.
    """

    kind: str
    start: tuple[float, float]
    end: tuple[float, float]
    feed: float | None
    center: tuple[float, float] | None = None
    ccw: bool = False
    turns: int = 0
    line: int = 1
    block_number: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in MOVE_KINDS:
            raise ConfigError("Move.kind", f"must be one of {MOVE_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "start", _point(self.start, "Move.start"))
        object.__setattr__(self, "end", _point(self.end, "Move.end"))
        _check_line(self.line, "Move.line")
        if self.kind == "rapid":
            if self.feed is not None:
                raise ConfigError("Move.feed", f"must be None for a rapid, got {self.feed!r}")
        elif not (isinstance(self.feed, float | int) and math.isfinite(self.feed)
                  and self.feed > 0.0):
            raise ConfigError("Move.feed", f"must be a finite feed > 0 (m/s), got {self.feed!r}")
        if self.kind != "arc":
            if self.center is not None or self.turns != 0:
                raise ConfigError("Move.center", "only arcs have a centre and turns")
            return
        if not isinstance(self.turns, int) or self.turns < 0:
            raise ConfigError("Move.turns", f"must be an int >= 0, got {self.turns!r}")
        if not isinstance(self.ccw, bool):
            raise ConfigError("Move.ccw", f"must be a bool, got {self.ccw!r}")
        center = _point(self.center, "Move.center")
        object.__setattr__(self, "center", center)
        r0 = math.dist(self.start, center)
        r1 = math.dist(self.end, center)
        scale = max(1.0, *(abs(value) for value in (*self.start, *center)))
        if r0 == 0.0 or abs(r1 - r0) > _RADIUS_MATCH * scale:
            raise ConfigError("Move.center", f"must be equidistant (> 0) from start and end, "
                                             f"got radii {r0!r} and {r1!r} (m)")

    @property
    def radius(self) -> float:
        """Arc radius (m); 0.0 for rapids and lines."""
        return 0.0 if self.center is None else math.dist(self.start, self.center)

    @property
    def sweep(self) -> float:
        """Signed angle swept by an arc (rad): > 0 counter-clockwise, full turns included;
        0.0 for rapids and lines."""
        if self.center is None:
            return 0.0
        return arc_sweep(self.start, self.end, self.center, ccw=self.ccw, turns=self.turns)

    @property
    def length(self) -> float:
        """Path length (m)."""
        if self.center is None:
            return math.dist(self.start, self.end)
        return self.radius * abs(self.sweep)


_new = object.__new__
_slots = {name: Move.__dict__[name].__set__ for name in
          ("kind", "start", "end", "feed", "center", "ccw", "turns", "line", "block_number")}


def trusted_move(kind: str, start: tuple[float, float], end: tuple[float, float],
                 feed: float | None, line: int, block_number: int | None) -> Move:
    """A line or rapid ``Move`` from the reader's own checked values, without the checks of
    ``Move.__post_init__`` (the reader's fast path, ``Interpreter.fast_line``); equal to
    ``Move(kind, start, end, feed, line=line, block_number=block_number)``."""
    move = _new(Move)
    s = _slots
    s["kind"](move, kind)
    s["start"](move, start)
    s["end"](move, end)
    s["feed"](move, feed)
    s["center"](move, None)
    s["ccw"](move, False)
    s["turns"](move, 0)
    s["line"](move, line)
    s["block_number"](move, block_number)
    return move


@dataclass(frozen=True, slots=True)
class Dwell:
    """G4: stand still.

    Attributes
    ----------
    duration : float
        Dwell time (s), >= 0.
    line : int
        1-based source line.
    """

    duration: float
    line: int = 1

    def __post_init__(self) -> None:
        if not (isinstance(self.duration, float | int) and math.isfinite(self.duration)
                and self.duration >= 0.0):
            raise ConfigError("Dwell.duration", f"must be >= 0 (s), got {self.duration!r}")
        _check_line(self.line, "Dwell.line")


@dataclass(frozen=True, slots=True)
class Event:
    """A machine function the motion stack passes on: spindle, tool, coolant.

    Attributes
    ----------
    kind : str
        One of ``EVENT_KINDS``.
    value : float or None
        Spindle speed (rad/s) for ``"spindle_speed"``, tool number for ``"tool_select"`` and
        ``"tool_change"``, the code (``"M0"``) for ``"pause"``, otherwise None.
    line : int
        1-based source line.
    """

    kind: str
    value: float | str | None = None
    line: int = 1

    def __post_init__(self) -> None:
        if self.kind not in EVENT_KINDS:
            raise ConfigError("Event.kind", f"must be one of {EVENT_KINDS}, got {self.kind!r}")
        _check_line(self.line, "Event.line")


@dataclass(frozen=True, slots=True)
class ProgramEnd:
    """M2 or M30: the program ends here; nothing after it runs.

    Attributes
    ----------
    code : str
        ``"M2"`` or ``"M30"``.
    line : int
        1-based source line.
    """

    code: str
    line: int = 1

    def __post_init__(self) -> None:
        if self.code not in ("M2", "M30"):
            raise ConfigError("ProgramEnd.code", f"must be 'M2' or 'M30', got {self.code!r}")
        _check_line(self.line, "ProgramEnd.line")


PATH_MODES = ("exact_stop", "exact_path", "blend")
"""``PathControl.mode`` values: G61.1, G61 and G64."""


@dataclass(frozen=True, slots=True)
class PathControl:
    """G61, G61.1 or G64: how the moves that follow join (LinuxCNC's path control).

    Attributes
    ----------
    mode : str
        ``"exact_stop"`` (G61.1: stop at the end of every move), ``"exact_path"`` (G61: the
        corners are not rounded) or ``"blend"`` (G64: corners rounded, by the machine's
        setting or within ``tolerance``).
    tolerance : float or None
        G64 P: the largest deviation from the path that rounding a corner may take (m);
        None: the machine's own (``controller.corner_blend`` of the contour tolerance).
    merge : float or None
        G64 Q: successive feed lines whose points lie within this of one straight line are
        run as that line (m); None: no merging.
    line : int
        1-based source line.
    """

    mode: str
    tolerance: float | None = None
    merge: float | None = None
    line: int = 1

    def __post_init__(self) -> None:
        if self.mode not in PATH_MODES:
            raise ConfigError("PathControl.mode", f"must be one of {PATH_MODES}, got "
                                                  f"{self.mode!r}")
        for name in ("tolerance", "merge"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"PathControl.{name}", f"must be >= 0 (m), got {value!r}")
        _check_line(self.line, "PathControl.line")


Item = Move | Dwell | Event | ProgramEnd | PathControl
"""Anything the reader yields, in execution order."""


@dataclass(frozen=True, slots=True)
class Program:
    """A whole parsed program: its items in execution order and its source text.

    Attributes
    ----------
    items : tuple
        ``Move``, ``Dwell``, ``Event`` and ``ProgramEnd`` items in execution order.
    text : str
        The source text it was parsed from.
    """

    items: tuple[Item, ...]
    text: str = ""

    @property
    def moves(self) -> tuple[Move, ...]:
        """Only the ``Move`` items, in order."""
        return tuple(item for item in self.items if isinstance(item, Move))

    @property
    def path_length(self) -> float:
        """Length of every move, rapids included (m)."""
        return math.fsum(move.length for move in self.moves)

    @property
    def feed_length(self) -> float:
        """Length of the feed moves (G1, G2, G3) only (m): the cut length of seed 001."""
        return math.fsum(move.length for move in self.moves if move.kind != "rapid")

    @property
    def end(self) -> ProgramEnd | None:
        """The closing M2/M30, None when the text simply ran out."""
        last = self.items[-1] if self.items else None
        return last if isinstance(last, ProgramEnd) else None

    def __iter__(self) -> Iterator[Item]:
        return iter(self.items)

    def __len__(self) -> int:
        return len(self.items)
