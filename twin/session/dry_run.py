"""A dry run: the program planned and interpolated against the machine's limits, without the
drives, the regulator or the physics. It never trips.

``twin run --dry-run`` (and ``twin jog --dry-run``) answers what an engineer asks before the
machine moves: does the program read, plan and stay inside the work zone (the soft limits:
refused, naming the line, as a real run would be), how long will it take, how long is the
path, and how close does the planned reference come to each axis' velocity, acceleration
and jerk limits. The reference is the controller's own (the planner and interpolator of
``Controller.from_machine``, at the controller period), so the cycle time is the real run's
less its settling. The ``.rrd`` holds the programmed path and the planned reference (path,
feed, per-axis velocity); the ``.json`` the figures.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES
from twin.controller.interpolator import InterpolatorStatus
from twin.session.record import make_sink, parse_command
from twin.session.setup import RunSpec, prepare
from twin.system.jsonio import output_dir, record_id, write_json_atomic
from twin.telemetry.channels import programmed_polyline, style_series, to_shown
from twin.units import MM_PER_MIN

__all__ = ["dry_run"]

_MOVING = (InterpolatorStatus.WORKING, InterpolatorStatus.DWELLING)
_CHUNK = 4096
"""Ticks sent to the recording at a time."""


class _Peaks:
    """Running per-axis maxima of |v|, |a|, |j| and of the feed, and the bounding box."""

    def __init__(self) -> None:
        self.v = np.zeros(2)
        self.a = np.zeros(2)
        self.j = np.zeros(2)
        self.feed = 0.0
        self.lo = np.full(2, np.inf)
        self.hi = np.full(2, -np.inf)
        self.travel = 0.0
        """Length of the planned path (m): the reference speed integrated over the ticks."""

    def add(self, p: np.ndarray, v: np.ndarray, a: np.ndarray, j: np.ndarray,
            period: float) -> None:
        self.travel += float(np.hypot(*v.T).sum()) * period
        self.v = np.maximum(self.v, np.abs(v).max(axis=0))
        self.a = np.maximum(self.a, np.abs(a).max(axis=0))
        self.j = np.maximum(self.j, np.abs(j).max(axis=0))
        self.feed = max(self.feed, float(np.hypot(*v.T).max()))
        self.lo = np.minimum(self.lo, p.min(axis=0))
        self.hi = np.maximum(self.hi, p.max(axis=0))


def dry_run(spec: RunSpec, *, out_dir: str | Path = "runs", run_id: str | None = None,
            rerun: str = "file") -> dict[str, Any]:
    """Plan and interpolate ``spec``'s program (or its manual commands) at the controller
    period; write ``<run_id>.json`` (and the ``.rrd`` that ``rerun`` names) and return the
    summary.

    Raises
    ------
    ConfigError, GCodeError, PlanningError
        The program cannot be read or planned, or leaves the work zone (naming the line),
        exactly as a real run would refuse it.
    """
    run_id = run_id or record_id()
    out = output_dir(out_dir)
    p = prepare(dataclasses.replace(spec, drives_off=False))
    p.driver.close()       # nothing is driven: the plant only gave the start position
    ctrl, cfg = p.controller, p.cfg
    for command in spec.commands:
        parse_command(command)(ctrl)
    interp = ctrl.interpolator
    period = cfg.controller.period
    limit = spec.time_limit(cfg)
    sink, recording = make_sink(rerun, out, run_id)
    t_wall = time.perf_counter()
    peaks = _Peaks()
    ticks = 0
    ref = interp.reference
    try:
        style_series(sink, ["feed/commanded", *(f"axes/{ax}/{q}/reference" for ax in AXES
                                                 for q in ("position", "velocity"))])
        if p.path:
            sink.static_path("path/programmed", to_shown("mm", programmed_polyline(p.path)))
        buf = np.empty((_CHUNK, 9))
        n = 0
        status = interp.status
        while status in _MOVING and ticks * period < limit:
            status = interp.update()
            ticks += 1
            row = buf[n]
            row[0] = ref.time
            row[1:3] = ref.position
            row[3:5] = ref.velocity
            row[5:7] = ref.acceleration
            row[7:9] = ref.jerk
            n += 1
            if n == _CHUNK or status not in _MOVING:
                _flush(sink, peaks, buf[:n], period)
                n = 0
        if n:
            _flush(sink, peaks, buf[:n], period)
    finally:
        sink.close()
    timed_out = status in _MOVING
    summary = _summary(spec, cfg, p, run_id, recording, peaks, ticks * period,
                       time.perf_counter() - t_wall, interp, timed_out, limit)
    write_json_atomic(out / f"{run_id}.json", summary)
    return summary


def _flush(sink: Any, peaks: _Peaks, rows: np.ndarray, period: float) -> None:
    t, pos, vel = rows[:, 0], rows[:, 1:3], rows[:, 3:5]
    peaks.add(pos, vel, rows[:, 5:7], rows[:, 7:9], period)
    cols = {"feed/commanded": to_shown("mm/min", np.hypot(*vel.T))}
    for k, ax in enumerate(AXES):
        cols[f"axes/{ax}/position/reference"] = to_shown("mm", pos[:, k])
        cols[f"axes/{ax}/velocity/reference"] = to_shown("mm/min", vel[:, k])
    sink.scalars(t, cols)
    sink.points(t, {"path/reference": to_shown("mm", pos)})


def _ratio(value: float, limit: float) -> float:
    return value / limit if limit > 0 else math.inf


def _summary(spec: RunSpec, cfg: Any, p: Any, run_id: str, recording: str | None,
             peaks: _Peaks, cycle: float, wall: float, interp: Any, timed_out: bool,
             limit: float) -> dict[str, Any]:
    axes = {}
    for k, ax in enumerate(AXES):
        lim = cfg.axes[ax].limits
        axes[ax] = {q: {"peak": peak * scale, "limit": top * scale, "unit": unit,
                        "ratio": _ratio(peak, top)}
                    for q, peak, top, scale, unit in (
                        ("velocity", peaks.v[k], lim.max_velocity, 1 / MM_PER_MIN, "mm/min"),
                        ("acceleration", peaks.a[k], lim.max_acceleration, 1.0, "m/s²"),
                        ("jerk", peaks.j[k], lim.max_jerk, 1.0, "m/s³"))}
    over = sorted(f"{ax} {q}" for ax, d in axes.items()
                  for q in ("velocity", "acceleration") if d[q]["ratio"] > 1.0 + 1e-9)
    lo, hi = (peaks.lo, peaks.hi) if math.isfinite(peaks.lo[0]) else (np.zeros(2),) * 2
    zone = p.controller.planner.work_zone
    error = interp.error
    status = "FINISHED" if error is None and not timed_out else (
        "TIMEOUT" if timed_out else "PROGRAM_ERROR")
    out: dict[str, Any] = {
        "run_id": run_id, "dry_run": True, "status": status, "machine": cfg.name,
        "program": spec.program or (None if spec.builtin == "none" else spec.builtin),
        "commands": list(spec.commands), "cycle_time_s": cycle,
        # the programmed path's length, as a run's summary gives it (a jog: its travel);
        # the planned reference rounds the corners, a little shorter
        "path_length_mm": (sum(seg.length for seg in p.path) if p.path else peaks.travel)
        * 1e3,
        "planned_travel_mm": peaks.travel * 1e3,
        "peak_feed_mm_per_min": peaks.feed / MM_PER_MIN,
        "feed_limit_mm_per_min": cfg.controller.limits.max_velocity / MM_PER_MIN,
        "axes": axes, "over_limits": over,
        "extent_mm": {ax: [lo[k] * 1e3, hi[k] * 1e3] for k, ax in enumerate(AXES)},
        "work_zone_mm": None if zone is None else {
            ax: [zone.lower[k] * 1e3, zone.upper[k] * 1e3] for k, ax in enumerate(AXES)},
        "wall_time_s": wall, "recording": recording, "spec": spec.to_dict(),
    }
    if error is not None:
        out["error"] = str(error)
    if timed_out:
        out["timeout"] = f"max_time ({limit:g} s) reached before the program ended"
    return out
