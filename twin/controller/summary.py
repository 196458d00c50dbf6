"""One run's metrics in one object: ``summarize`` → ``RunMetrics`` → ``to_report()``.

``to_report`` is the one place that converts the SI metrics to µm, mm and mm/min.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from twin.controller.geometry import Segment
from twin.controller.io import AXES
from twin.controller.metrics import (
    _times,
    _unit,
    _xy,
    contour_error,
    coordinate_error,
    productivity,
    velocity_error,
)
from twin.errors import ConfigError
from twin.units import to_mm, to_mm_per_min, to_um

__all__ = ["RunMetrics", "RunningSummary", "summarize"]

_PER_AXIS = ("max_coordinate_error", "rms_coordinate_error", "max_velocity_error",
             "rms_velocity_error")


@dataclass(frozen=True)
class RunMetrics:
    """Every metric of one run, SI. ``to_report()`` gives µm, mm, mm/min and s.

    Attributes
    ----------
    samples : int
        Number of samples.
    max_coordinate_error, rms_coordinate_error : tuple of float, (x, y)
        Largest absolute and RMS coordinate error per axis (m).
    max_contour_error, rms_contour_error : float
        Largest and RMS contour error (m).
    max_vector_error, rms_vector_error : float
        Largest and RMS vector error (m).
    max_velocity_error, rms_velocity_error : tuple of float, (x, y)
        Largest absolute and RMS velocity error per axis (m/s).
    settling_travel : float
        Peak deviation from the final position after the motion (m); NaN if the record
        stops with the motion.
    overshoot : float
        Travel past the programmed end point along the final tangent after the motion (m).
    cycle_time : float
        Program time, first to last commanded motion (s).
    path_length : float
        Length of the programmed path (m).
    productivity : float
        ``path_length / cycle_time`` (m/s); 0 if nothing moved.
    """

    samples: int
    max_coordinate_error: tuple[float, float]
    rms_coordinate_error: tuple[float, float]
    max_contour_error: float
    rms_contour_error: float
    max_vector_error: float
    rms_vector_error: float
    max_velocity_error: tuple[float, float]
    rms_velocity_error: tuple[float, float]
    settling_travel: float
    overshoot: float
    cycle_time: float
    path_length: float
    productivity: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            values = value if f.name in _PER_AXIS else (value,)
            if f.name in _PER_AXIS and len(values) != len(AXES):
                raise ConfigError(f.name, f"must hold one value per axis {AXES}, got {value!r}")
            if any(v < 0 for v in values):  # NaN passes: a diverged run has no value
                raise ConfigError(f.name, f"must be >= 0, got {value!r}")

    def to_report(self) -> dict[str, float]:
        """Flat dict for reports and JSON: lengths in µm (mm for the path), speeds in mm/min.

        Keys: ``samples``, ``max_coordinate_error_{x,y}_um``, ``rms_coordinate_error_{x,y}_um``,
        ``max_contour_error_um``, ``rms_contour_error_um``, ``max_vector_error_um``,
        ``rms_vector_error_um``, ``max_velocity_error_{x,y}_mm_per_min``,
        ``rms_velocity_error_{x,y}_mm_per_min``, ``settling_travel_um``, ``overshoot_um``,
        ``cycle_time_s``, ``path_length_mm``, ``productivity_mm_per_min``.
        """
        report: dict[str, float] = {"samples": self.samples}
        for name in ("max_coordinate_error", "rms_coordinate_error"):
            for axis, value in zip(AXES, getattr(self, name), strict=True):
                report[f"{name}_{axis}_um"] = to_um(value)
        for name in ("max_contour_error", "rms_contour_error", "max_vector_error",
                     "rms_vector_error"):
            report[f"{name}_um"] = to_um(getattr(self, name))
        for name in ("max_velocity_error", "rms_velocity_error"):
            for axis, value in zip(AXES, getattr(self, name), strict=True):
                report[f"{name}_{axis}_mm_per_min"] = to_mm_per_min(value)
        report["settling_travel_um"] = to_um(self.settling_travel)
        report["overshoot_um"] = to_um(self.overshoot)
        report["cycle_time_s"] = self.cycle_time
        report["path_length_mm"] = to_mm(self.path_length)
        report["productivity_mm_per_min"] = to_mm_per_min(self.productivity)
        return report


class RunningSummary:
    """The metrics of a run fed in blocks of samples, in constant memory: what
    :func:`summarize` gives on the whole record (to rounding: the RMS values are running
    sums of squares).

    Blocks are gathered up to ``block`` samples before they are measured, so a program of
    many segments is searched once per block rather than once per small feed. After the
    motion only what the after-motion metrics need is kept: the largest overshoot since the
    last moving sample, and the points since then for the settling travel (compacted to
    their convex hull past ``block`` points: the point farthest from the final position is
    a vertex of it). Sample times must increase strictly.

    Parameters
    ----------
    path : sequence of Segment
        The programmed path.
    t_end : float, optional
        End of the commanded motion (s); default: the sample after the last moving one.
    window : int
        Segments searched on each side of the ``segment`` hint (see :func:`contour_error`).
    block : int
        Samples measured at a time (≥ 1).
    """

    def __init__(self, path: Sequence[Segment], *, t_end: float | None = None,
                 window: int = 1, block: int = 65536):
        self.segments = list(path)
        if not self.segments:
            raise ValueError("path must hold at least one segment")
        if block < 1:
            raise ValueError(f"block must be >= 1 sample, got {block}")
        self.t_end, self.window, self.block = t_end, window, int(block)
        last = self.segments[-1]
        self._target = np.asarray(last.end, dtype=float)
        self._direction = _unit("direction", last.end_tangent)
        self._waiting: list[tuple[np.ndarray, ...]] = []
        self._waiting_n = 0
        self.samples = 0
        self._sq = np.zeros(6)         # coordinate x, y; vector; velocity x, y; contour
        self._max = np.zeros(6)
        self._first_t = math.nan       # the first moving sample's time
        self._last = -1                # index of the last moving sample
        self._stop_t = math.nan        # time of the sample after it
        self._end_t = math.nan         # time of the last sample
        self._end_pos = np.full(2, math.nan)
        self._over = -math.inf         # overshoot past the end, over the tail
        self._tail: list[np.ndarray] = []   # settling candidates (points, or their hull)
        self._tail_n = 0

    def feed(self, t, ref_position, ref_velocity, position, velocity, segment=None) -> None:
        """Add samples: ``t`` (n,), the others (n, 2) as :func:`summarize` takes them."""
        pos = _xy("position", position)
        n = pos.shape[0]
        if n == 0:
            return
        part = (_times(t, n).copy(), _xy("ref_position", ref_position, n).copy(),
                _xy("ref_velocity", ref_velocity, n).copy(), pos.copy(),
                _xy("velocity", velocity, n).copy(),
                None if segment is None else np.asarray(segment).copy())
        self._waiting.append(part)
        self._waiting_n += n
        if self._waiting_n >= self.block:
            self._measure()

    def _measure(self) -> None:
        if not self._waiting:
            return
        t, ref, ref_vel, pos, vel, seg = (
            None if any(p[k] is None for p in self._waiting)
            else np.concatenate([p[k] for p in self._waiting]) for k in range(6))
        self._waiting.clear()
        self._waiting_n = 0
        coord = coordinate_error(ref, pos)
        errors = (np.abs(coord), np.hypot(*coord.T)[:, None],
                  np.abs(velocity_error(ref_vel, vel)),
                  contour_error(self.segments, pos, hint=seg, window=self.window)[:, None])
        values = np.concatenate(errors, axis=1)              # (n, 6)
        self._sq += np.square(values).sum(axis=0)
        self._max = np.maximum(self._max, values.max(axis=0))     # NaN stays NaN
        n0, n = self.samples, len(t)
        self.samples += n
        self._end_t, self._end_pos = float(t[-1]), pos[-1].copy()
        past = (pos - self._target) @ self._direction
        if self._last == n0 - 1 and self._last >= 0:    # the previous block ended moving
            self._stop_t = float(t[0])
        moving = np.flatnonzero(np.any(ref_vel != 0.0, axis=1))
        if moving.size:
            j = int(moving[-1])
            if math.isnan(self._first_t):
                self._first_t = float(t[moving[0]])
            self._last = n0 + j
            self._stop_t = float(t[j + 1]) if j + 1 < n else math.nan
        if self.t_end is not None:          # a given end: the tails are fixed in time
            self._extend(past[t >= self.t_end], pos[t > self.t_end])
        elif moving.size:                   # the tails start again after this motion
            self._over, self._tail, self._tail_n = -math.inf, [], 0
            self._extend(past[j + 1:], pos[j + 2:])
        else:
            # the tails start one (overshoot) and two (settling) samples after the last
            # moving one; with no moving sample at all t_end is the first sample's time
            o = max(self._last + 1 - n0, 0)
            s = max(self._last + 2 - n0, 0) if self._last >= 0 else max(1 - n0, 0)
            self._extend(past[o:], pos[s:])

    def _extend(self, past: np.ndarray, points: np.ndarray) -> None:
        if past.size:
            self._over = float(np.maximum(self._over, past.max()))   # NaN stays NaN
        if len(points):
            self._tail.append(points)
            self._tail_n += len(points)
            if self._tail_n > self.block:
                hull = _hull(np.concatenate(self._tail))
                self._tail, self._tail_n = [hull], len(hull)

    def result(self) -> RunMetrics:
        """The metrics of everything fed so far."""
        self._measure()
        n = self.samples
        if n == 0:
            raise ValueError("a run needs at least one sample")
        rms = np.sqrt(self._sq / n)
        if self._last < 0:
            duration = 0.0
        else:
            stop = self._end_t if math.isnan(self._stop_t) else self._stop_t
            duration = float(stop - self._first_t)
        over = self._over
        if self.t_end is None and self._last == n - 1:   # moving to the end: t_end is the
            over = float((self._end_pos - self._target) @ self._direction)   # last sample
        travel = (float(np.hypot(*(np.concatenate(self._tail) - self._end_pos).T).max())
                  if self._tail_n else math.nan)
        length = math.fsum(seg.length for seg in self.segments)
        return RunMetrics(
            samples=n,
            max_coordinate_error=(float(self._max[0]), float(self._max[1])),
            rms_coordinate_error=(float(rms[0]), float(rms[1])),
            max_contour_error=float(self._max[5]),
            rms_contour_error=float(rms[5]),
            max_vector_error=float(self._max[2]),
            rms_vector_error=float(rms[2]),
            max_velocity_error=(float(self._max[3]), float(self._max[4])),
            rms_velocity_error=(float(rms[3]), float(rms[4])),
            settling_travel=travel,
            overshoot=max(over, 0.0),
            cycle_time=duration,
            path_length=length,
            productivity=productivity(length, duration) if duration > 0.0 else 0.0,
        )


def _hull(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of points (m, 2): the extremes along the line when
    they are collinear, the point when they coincide."""
    from scipy.spatial import ConvexHull, QhullError

    finite = points[np.isfinite(points).all(axis=1)]
    if len(finite) < len(points):       # a diverged run: keep one NaN, max stays NaN
        return np.concatenate((_hull(finite) if len(finite) else finite, points[~np.isfinite(
            points).all(axis=1)][:1]))
    try:
        return points[ConvexHull(points).vertices]
    except (QhullError, ValueError):    # fewer than 3 points, collinear or coincident
        d = points - points[0]
        axis = d[np.argmax(np.hypot(*d.T))] if len(points) > 1 else np.zeros(2)
        along = d @ axis
        return points[[int(np.argmin(along)), int(np.argmax(along))]]


def summarize(t, ref_position, ref_velocity, position, velocity, path: Sequence[Segment], *,
              segment=None, t_end: float | None = None, window: int = 1) -> RunMetrics:
    """All metrics of a recorded run (:class:`RunningSummary` fed the whole record at once).

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times (s), increasing, n ≥ 1.
    ref_position, position : array_like, shape (n, 2)
        Reference and actual position (m).
    ref_velocity, velocity : array_like, shape (n, 2)
        Reference and actual velocity (m/s).
    path : sequence of Segment
        The programmed path.
    segment : array_like of int, shape (n,), optional
        Active segment per sample; speeds up the contour error (see :func:`contour_error`).
    t_end : float, optional
        End of the commanded motion (s). Default: the sample after the last one with a
        non-zero reference velocity.
    window : int
        Segments searched on each side of ``segment`` for the contour error.

    Returns
    -------
    RunMetrics
        Samples that move are those with a non-zero reference velocity; settling travel
        is measured after ``t_end`` about the final position, overshoot after ``t_end``
        past the end of the path along its final tangent.
    """
    pos = _xy("position", position)
    n = pos.shape[0]
    if n == 0:
        raise ValueError("a run needs at least one sample")
    running = RunningSummary(path, t_end=t_end, window=window, block=n)
    running.feed(t, ref_position, ref_velocity, pos, velocity, segment)
    return running.result()
