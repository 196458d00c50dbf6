"""Test programs for tuning runs: the library's programs, whole or scaled down.

A tuning run must exercise what the gains act on — accelerations from rest, speed changes
between spline sections, a corner, a circle (axis reversals), a rapid — but every run costs
wall time. ``"compact"`` is the default program (``twin.controller.library.default_program``)
shrunk about its start point by ``COMPACT_SCALE``: the same feeds, accelerations and jerk
phases, about a twentieth of the path, so one run takes a few simulated seconds instead of
a minute; ``"tiny"`` shrinks it to 1 % for tests and smoke runs. ``"default"`` is the full
program, the one the acceptance figures are quoted on.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from twin.config import MachineConfig
from twin.controller.geometry import Arc, Line, Segment, SplinePath
from twin.controller.library import PROGRAMS as LIBRARY
from twin.controller.library import build_program
from twin.controller.planner import MotionBlock
from twin.errors import ConfigError

__all__ = ["COMPACT_SCALE", "PROGRAMS", "TINY_SCALE", "scale_segment", "scaled_program",
           "tuning_program"]

COMPACT_SCALE = 0.05
"""Length scale of the ``"compact"`` program relative to the default program (1)."""
TINY_SCALE = 0.01
"""Length scale of the ``"tiny"`` program (1)."""


def scale_segment(segment: Segment, origin: np.ndarray, factor: float) -> Segment:
    """``segment`` shrunk (``factor`` < 1) or grown about ``origin`` (m).

    Raises
    ------
    ConfigError
        For a segment type it cannot rebuild.
    """

    def s(p: Any) -> np.ndarray:
        return origin + factor * (np.asarray(p, dtype=float) - origin)

    if isinstance(segment, Line):
        return Line(s(segment.start), s(segment.end))
    if isinstance(segment, Arc):
        return Arc(s(segment.start), s(segment.end), s(segment.center), ccw=segment.ccw,
                   turns=segment.turns)
    if isinstance(segment, SplinePath):
        return SplinePath(s(segment.points))
    raise ConfigError("program", f"cannot scale a {type(segment).__name__} segment")


def scaled_program(items: Iterable[Any], origin: Sequence[float], factor: float) -> list[Any]:
    """Motion items with every segment scaled about ``origin`` (m) by ``factor``; feeds,
    dwells and other items unchanged."""
    if not (np.isfinite(factor) and factor > 0.0):
        raise ConfigError("factor", f"must be a finite number > 0, got {factor!r}")
    o = np.asarray(origin, dtype=float)
    return [MotionBlock(scale_segment(it.segment, o, factor), it.feed, it.line)
            if isinstance(it, MotionBlock) else it for it in items]


_SCALED = {"compact": COMPACT_SCALE, "tiny": TINY_SCALE}

PROGRAMS = (*_SCALED, *LIBRARY)
"""Program names a tuning run accepts: ``"compact"``, ``"tiny"`` and the library's."""


def tuning_program(name: str, cfg: MachineConfig, start: Sequence[float]) -> list[Any]:
    """The motion items of program ``name`` on machine ``cfg`` starting at ``start`` (m).

    Raises
    ------
    ConfigError
        For an unknown name (listing the valid ones).
    """
    if name in _SCALED:
        return scaled_program(build_program("default", cfg, start), start, _SCALED[name])
    if name in LIBRARY:
        return build_program(name, cfg, start)
    raise ConfigError("program", f"unknown tuning program {name!r}; valid: "
                      f"{', '.join(PROGRAMS)}")
