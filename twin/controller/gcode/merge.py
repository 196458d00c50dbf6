"""G64 Q: successive feed lines that lie within Q of one straight line run as that line.

LinuxCNC's "naive CAM detector" (``emccanon.cc``): CAM output often cuts a straight edge
into many collinear chords, each a block the planner must join. With ``G64 P… Q…`` in force,
a chain of G1 moves at one feed is run as one line from its first point to its last as long
as

* every point of the chain lies within Q of that line, and
* the points advance along it (a chain that turns back on itself is not merged),

and at most ``MAX_CHAIN`` points are merged into one line. Anything else (an arc, a rapid,
another feed, a dwell, an event, a ``PathControl``) ends the chain. The merged ``Move``
carries the first block's line and block number.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator

from twin.controller.gcode.items import Item, Move, PathControl

__all__ = ["MAX_CHAIN", "merge_lines"]

MAX_CHAIN = 64
"""Most programmed points merged into one line (bounds the work per line)."""


def _fits(points: list[tuple[float, float]], end: tuple[float, float], q: float) -> bool:
    """Whether every point lies within ``q`` of the segment from ``points[0]`` to ``end``
    and the points advance along it."""
    (x0, y0), (x1, y1) = points[0], end
    dx, dy = x1 - x0, y1 - y0
    length = math.hypot(dx, dy)
    if length == 0.0:
        return False
    ux, uy = dx / length, dy / length
    last = 0.0
    for px, py in points[1:]:
        along = (px - x0) * ux + (py - y0) * uy
        if along < last or along > length or abs((px - x0) * uy - (py - y0) * ux) > q:
            return False
        last = along
    return True


def merge_lines(items: Iterable[Item]) -> Iterator[Item]:
    """The reader's items with the chains G64 Q allows merged (see the module doc); without
    a ``PathControl`` that sets Q, the items unchanged."""
    q = None
    chain: list[tuple[float, float]] = []
    first: Move | None = None
    last: Move | None = None

    def flush() -> Iterator[Item]:
        if first is None:
            return
        if last is first:
            yield first
        else:
            yield Move("line", first.start, last.end, first.feed, line=first.line,
                       block_number=first.block_number)

    for item in items:
        if q is None:
            if type(item) is PathControl and item.merge:
                q = item.merge
            yield item
            continue
        if type(item) is Move and item.kind == "line":
            if first is not None and item.feed == first.feed and item.start == last.end \
                    and len(chain) < MAX_CHAIN and _fits([*chain, item.start], item.end, q):
                chain.append(item.start)
                last = item
                continue
            yield from flush()
            first = last = item
            chain = [item.start]
            continue
        yield from flush()
        first = last = None
        chain = []
        if type(item) is PathControl:
            q = item.merge or None
        yield item
    yield from flush()
