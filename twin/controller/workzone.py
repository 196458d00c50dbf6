"""Soft limits: the rectangle the tool may reach, checked per segment before motion.

The work zone of a machine is the travel of each axis narrowed to the inside of its end
limit switches (a position where a switch is actuated is outside). The planner checks every
segment's bounding box as it enters the look-ahead window, and the controller checks a whole
in-memory program before the first tick; a violation is a ``PlanningError`` naming the
G-code line.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from twin.config import AxisConfig
from twin.controller.geometry import Line, Segment
from twin.errors import ConfigError, PlanningError

__all__ = ["WorkZone"]


@dataclass(frozen=True)
class WorkZone:
    """The rectangle the tool may reach (soft limits).

    Attributes
    ----------
    lower, upper : tuple of float
        Corners (m), ``lower < upper`` on each axis.
    """

    lower: tuple[float, float]
    upper: tuple[float, float]

    def __post_init__(self) -> None:
        if not all(lo < hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise ConfigError("work_zone", f"need lower < upper, got {self.lower}, {self.upper}")

    @classmethod
    def from_axes(cls, axes: Mapping[str, AxisConfig]) -> WorkZone:
        """Travel of each axis, narrowed to the inside of its end limit switches."""
        lo = tuple(max(axes[a].mechanics.travel[0], axes[a].switches.limit_min) for a in "xy")
        hi = tuple(min(axes[a].mechanics.travel[1], axes[a].switches.limit_max) for a in "xy")
        return cls(lo, hi)  # type: ignore[arg-type]

    def contains(self, point: Sequence[float]) -> bool:
        """Whether ``point`` (m) lies in the zone (edges included)."""
        return (self.lower[0] <= point[0] <= self.upper[0]
                and self.lower[1] <= point[1] <= self.upper[1])

    def check(self, segment: Segment, line: int = 0) -> None:
        """Raise ``PlanningError`` naming ``line`` if ``segment`` leaves the zone."""
        if type(segment) is Line:
            inside = self.contains(segment.start.tolist()) and \
                self.contains(segment.end.tolist())
        else:
            lo, hi = segment.bounding_box()
            inside = self.contains(lo) and self.contains(hi)
        if not inside:
            box_lo, box_hi = segment.bounding_box()
            where = f"line {line}: the move" if line > 0 else "the move"   # a jog: no line
            mm = 1e3      # a message for people: millimetres, as the program and the DRO
            raise PlanningError(
                f"{where} leaves the work zone X {self.lower[0] * mm:.6g} … "
                f"{self.upper[0] * mm:.6g} mm, Y {self.lower[1] * mm:.6g} … "
                f"{self.upper[1] * mm:.6g} mm (it spans X {box_lo[0] * mm:.6g} … "
                f"{box_hi[0] * mm:.6g}, Y {box_lo[1] * mm:.6g} … {box_hi[1] * mm:.6g} mm)")
