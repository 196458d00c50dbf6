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
    _xy,
    contour_error,
    coordinate_error,
    cycle_time,
    overshoot,
    productivity,
    settling_travel,
    velocity_error,
)
from twin.errors import ConfigError
from twin.units import to_mm, to_mm_per_min, to_um

__all__ = ["RunMetrics", "summarize"]

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


def _rms(values: np.ndarray, axis=None):
    return np.sqrt(np.mean(np.square(values), axis=axis))


def summarize(t, ref_position, ref_velocity, position, velocity, path: Sequence[Segment], *,
              segment=None, t_end: float | None = None, window: int = 1) -> RunMetrics:
    """All metrics of a recorded run.

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
    times = _times(t, n)
    ref_pos = _xy("ref_position", ref_position, n)
    coord = coordinate_error(ref_pos, pos)
    vector = np.hypot(*coord.T)
    vel = velocity_error(_xy("ref_velocity", ref_velocity, n), _xy("velocity", velocity, n))
    contour = contour_error(path, pos, hint=segment, window=window)
    moving = np.any(np.asarray(ref_velocity, dtype=float) != 0.0, axis=1)
    duration = cycle_time(times, moving)
    if t_end is None:
        idx = np.flatnonzero(moving)
        t_end = float(times[min(int(idx[-1]) + 1, n - 1)]) if idx.size else float(times[0])
    try:
        travel = settling_travel(times, pos, t_end)
    except ValueError:
        travel = math.nan
    segments = list(path)
    length = math.fsum(seg.length for seg in segments)
    return RunMetrics(
        samples=n,
        max_coordinate_error=tuple(np.abs(coord).max(axis=0).tolist()),
        rms_coordinate_error=tuple(_rms(coord, axis=0).tolist()),
        max_contour_error=float(contour.max()),
        rms_contour_error=float(_rms(contour)),
        max_vector_error=float(vector.max()),
        rms_vector_error=float(_rms(vector)),
        max_velocity_error=tuple(np.abs(vel).max(axis=0).tolist()),
        rms_velocity_error=tuple(_rms(vel, axis=0).tolist()),
        settling_travel=travel,
        overshoot=overshoot(times, pos, segments[-1].end, segments[-1].end_tangent,
                            after=t_end),
        cycle_time=duration,
        path_length=length,
        productivity=productivity(length, duration) if duration > 0.0 else 0.0,
    )
