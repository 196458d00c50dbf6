"""A library of trajectories (seed 000's rig had one): built-in programs as motion items.

Each builder returns a list of planner items — ``MotionBlock``s (a segment and its feed),
``Dwell``s — that the ``Controller`` accepts like a parsed G-code program, scaled to the
machine's travel and speed so the same program exercises every machine.

``default_program`` is what ``twin run`` runs without a program file: seed 000's spline path
O-A-B-C with a different contour speed on each section (accelerate on OA, cruise faster on
AB, slow down on BC), a 90° corner (seed 001's corner study), and a full circle.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from twin.config import MachineConfig
from twin.controller.gcode import Dwell
from twin.controller.geometry import Arc, Line, Segment
from twin.controller.planner import MotionBlock, segments_from_program
from twin.controller.spline import natural_cubic
from twin.controller.spline_path import SplinePath
from twin.errors import ConfigError

__all__ = [
    "COMPACT_SCALE",
    "PROGRAMS",
    "TABLE2_FEED",
    "TINY_SCALE",
    "build_program",
    "compact_program",
    "default_program",
    "program_path",
    "scale_segment",
    "scaled_program",
    "spline_line",
    "square_corner",
    "table2_move",
    "tiny_program",
]



def _end_tangents(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents at the start and the end of the natural cubic spline through
    ``points`` (as `SplinePath` builds it: x(u), y(u) of the cumulative chord length u)."""
    u = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))))
    sp = natural_cubic(u, points)
    h = u[-1] - u[-2]
    start, end = sp.b[0], sp.b[-1] + 2.0 * sp.c[-1] * h + 3.0 * sp.d[-1] * h * h
    return start / np.linalg.norm(start), end / np.linalg.norm(end)


def _continuing(previous: np.ndarray, section: np.ndarray) -> np.ndarray:
    """``section`` with its second point moved along its normal so that its natural spline
    leaves its first point along ``previous``' end tangent: the two sections then meet
    tangentially, and both natural ends have zero curvature there (G2)."""
    want = _end_tangents(previous)[1]
    chord = section[2] - section[0]
    normal = np.array([-chord[1], chord[0]]) / np.linalg.norm(chord)

    def turn(d: float) -> float:
        moved = section.copy()
        moved[1] = section[1] + d * normal
        t = _end_tangents(moved)[0]
        return float(want[0] * t[1] - want[1] * t[0])    # sin of the angle between them

    reach = 0.5 * float(np.linalg.norm(chord))
    out = section.copy()
    from scipy.optimize import brentq  # here: half a second of every process' start

    out[1] = section[1] + brentq(turn, -reach, reach, xtol=1e-15) * normal
    return out


def _tangent_sections(*sections: Sequence[Sequence[float]]) -> tuple[np.ndarray, ...]:
    """Seed 000's trajectory is built of spline sections that meet without a velocity jump
    (the sections' speeds change, not their direction): each section after the first is
    made to continue the one before it tangentially (``_continuing``)."""
    out = [np.asarray(sections[0], dtype=float)]
    for section in sections[1:]:
        out.append(_continuing(out[-1], np.asarray(section, dtype=float)))
    return tuple(out)


# Shape of the default program in units of the program scale L, relative to its start O:
# O-A-B-C as three natural splines that meet tangentially at A and B (the second point of
# A-B and of B-C is placed for it, within 0.01·L of (1.0, 0.45) and (1.7, 0.8)).
@functools.cache
def _sections() -> tuple[np.ndarray, ...]:
    """O-A, A-B and B-C (built when first asked for: it needs a root finder)."""
    return _tangent_sections(
        ((0.0, 0.0), (0.25, 0.05), (0.5, 0.15), (0.75, 0.3)),
        ((0.75, 0.3), (1.0, 0.45), (1.25, 0.6), (1.5, 0.7)),
        ((1.5, 0.7), (1.7, 0.8), (1.85, 0.95), (1.9, 1.1)))
_D = (1.9, 1.6)
_E = (1.3, 1.6)
_CIRCLE_RADIUS = 0.3


def _scale(cfg: MachineConfig) -> float:
    """Program scale L (m): the default program spans 1.9·L × 1.6·L."""
    spans = [ax.switches.limit_max - ax.switches.limit_min for ax in cfg.axes.values()]
    return 0.45 * min(spans)


def default_program(cfg: MachineConfig, start: Sequence[float]) -> list[Any]:
    """Seed 000's O-A-B-C spline sections, a corner, a circle; back to O at rapid speed.

    Parameters
    ----------
    cfg : MachineConfig
        Sets the size (from the switch span) and the feeds (from the contour limit).
    start : sequence of 2 float
        The point O (m), normally where the table is (the home position).
    """
    o = np.asarray(start, dtype=float)
    scale = _scale(cfg)
    v = cfg.controller.limits.max_velocity

    def pts(rel: Iterable[Sequence[float]]) -> np.ndarray:
        return o + scale * np.asarray(rel, dtype=float)

    oa, ab, bc = _sections()
    c, d, e = pts([bc[-1]])[0], pts([_D])[0], pts([_E])[0]
    centre = e - np.array([0.0, _CIRCLE_RADIUS * scale])
    return [
        MotionBlock(SplinePath(pts(oa)), 0.5 * v),     # O-A: accelerate, cruise
        MotionBlock(SplinePath(pts(ab)), 0.9 * v),     # A-B: faster contour speed
        MotionBlock(SplinePath(pts(bc)), 0.4 * v),     # B-C: slow down
        MotionBlock(Line(c, d), 0.7 * v),               # corner at D: 90° left turn
        MotionBlock(Line(d, e), 0.7 * v),
        MotionBlock(Arc(e, e, centre, ccw=True), 0.6 * v),  # full circle
        Dwell(duration=0.2),
        MotionBlock(Line(e, o), None),                  # rapid back to O
    ]


def spline_line(cfg: MachineConfig, start: Sequence[float], *, length: float | None = None,
                axis: int = 0, points: int = 6, feed: float | None = None) -> list[Any]:
    """A straight move along one axis described by a spline (seed 000, Table 2's test).

    ``points`` equally spaced knots on the line give a natural spline that *is* the line.
    """
    o = np.asarray(start, dtype=float)
    length = _scale(cfg) * 1.5 if length is None else length
    direction = np.zeros(2)
    direction[axis] = 1.0
    knots = o + np.linspace(0.0, length, points)[:, None] * direction
    v = cfg.controller.limits.max_velocity if feed is None else feed
    return [MotionBlock(SplinePath(knots), v)]


TABLE2_FEED = 0.44e-3
"""Seed 000, Table 2's straight X move at about 26 mm/min (m/s): the feed of a rig whose
position loop lagged it by 30 µm (``twin.analysis.studies.seed000_dcu`` sizes it from the twin's own
velocity gain; this is the figure for the rig's)."""


def table2_move(cfg: MachineConfig, start: Sequence[float]) -> list[Any]:
    """Seed 000, Table 2's test: 1.2 mm along X described by a spline at ``TABLE2_FEED``
    (``twin run --builtin spline_line``)."""
    return spline_line(cfg, start, length=1.2e-3, feed=TABLE2_FEED)


def square_corner(cfg: MachineConfig, start: Sequence[float], *, angle: float = np.pi / 2,
                  length: float | None = None, feed: float | None = None) -> list[Any]:
    """Two lines A-B, B-C meeting at B with the direction turning by ``angle`` (rad)."""
    a = np.asarray(start, dtype=float)
    length = _scale(cfg) * 0.8 if length is None else length
    b = a + np.array([length, 0.0])
    c = b + length * np.array([np.cos(angle), np.sin(angle)])
    v = cfg.controller.limits.max_velocity if feed is None else feed
    return [MotionBlock(Line(a, b), v), MotionBlock(Line(b, c), v)]


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


def compact_program(cfg: MachineConfig, start: Sequence[float]) -> list[Any]:
    """The default program shrunk about its start by ``COMPACT_SCALE``: the same feeds,
    accelerations and jerk phases on a twentieth of the path (the tuning runs' program)."""
    return scaled_program(default_program(cfg, start), start, COMPACT_SCALE)


def tiny_program(cfg: MachineConfig, start: Sequence[float]) -> list[Any]:
    """The default program shrunk to ``TINY_SCALE`` (tests and smoke runs)."""
    return scaled_program(default_program(cfg, start), start, TINY_SCALE)


PROGRAMS = {"default": default_program, "compact": compact_program, "tiny": tiny_program,
            "spline_line": table2_move,
            "corner": square_corner}
"""Built-in programs by name: ``twin run --builtin NAME``."""


def build_program(name: str, cfg: MachineConfig, start: Sequence[float],
                  **options: Any) -> list[Any]:
    """A built-in program by name (see ``PROGRAMS``)."""
    if name not in PROGRAMS:
        raise ConfigError("builtin", f"unknown built-in program {name!r}; valid: "
                          f"{', '.join(PROGRAMS)}")
    return PROGRAMS[name](cfg, start, **options)


def program_path(items: Iterable[Any]) -> list[Segment]:
    """The programmed path: the segments of the motion blocks, in block order (the
    ``block`` index of the controller's record indexes this list)."""
    return [item.segment for item in segments_from_program(items)
            if isinstance(item, MotionBlock)]
