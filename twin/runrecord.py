"""The parts of a run record: the metric summary, the telemetry sink a ``--rerun`` option
names, the deadline report, and manual-mode commands (the files themselves are written by
``twin.jsonio``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES
from twin.controller.controller import Controller
from twin.controller.summary import summarize
from twin.errors import ConfigError
from twin.hardware.realtime import TickStats
from twin.telemetry.sink import NullSink, Sink

__all__ = ["make_sink", "parse_command", "run_summary", "ticks_dict"]


def make_sink(rerun: str, out: Path, run_id: str) -> tuple[Sink, str | None]:
    """The sink ``--rerun`` names: spawn, serve, none, file (``out/<run_id>.rrd``) or a path
    ending in ``.rrd``; spawn and serve also write the file. Returns (sink, .rrd path)."""
    if rerun == "none":
        return NullSink(), None
    from twin.telemetry.rerun_sink import RerunSink

    if rerun.endswith(".rrd"):
        path, live = Path(rerun), None
    elif rerun in ("file", "spawn", "serve"):
        path, live = out / f"{run_id}.rrd", None if rerun == "file" else rerun
    else:
        raise ConfigError("rerun", f"must be spawn, serve, none, file or a path ending in "
                          f".rrd, got {rerun!r}")
    return RerunSink(path, live=live, recording_id=run_id, recording_name=run_id), str(path)


def ticks_dict(stats: TickStats) -> dict[str, Any]:
    """The deadline report as the summary's ``ticks`` object."""
    d = stats.to_dict()
    return {k: d[k] for k in ("due", "on_time", "late", "skipped", "jitter_p50_us",
                              "jitter_p99_us", "jitter_max_us", "on_time_ratio", "paced")}


def run_summary(rec: Mapping[str, np.ndarray], path: list) -> dict[str, Any]:
    """The metric part of the summary (µm, mm, s) from a run's record.

    The actual velocity is the twin's table velocity when the record has it (a simulated
    run), else the derivative of the measured position (real I/O)."""
    if len(rec["t"]) < 2 or not path:
        return {"cycle_time_s": 0.0, "path_length_mm": 0.0}
    velocity = rec.get("table_velocity")
    if velocity is None:
        velocity = np.gradient(rec["position"], rec["t"], axis=0)
    # No active-block hint: a table lagging several short blocks behind its reference would
    # be measured against the wrong ones. The exact search over the whole path is cheap.
    m = summarize(rec["t"], rec["ref_position"], rec["ref_velocity"], rec["position"],
                  velocity, path)
    r = m.to_report()
    return {
        "cycle_time_s": r["cycle_time_s"],
        "path_length_mm": r["path_length_mm"],
        "max_contour_error_um": r["max_contour_error_um"],
        "rms_contour_error_um": r["rms_contour_error_um"],
        "max_coordinate_error_um": {a: r[f"max_coordinate_error_{a}_um"] for a in AXES},
        "max_velocity_error_um_s": {
            a: m.max_velocity_error[i] * 1e6 for i, a in enumerate(AXES)},
        "max_vector_error_um": r["max_vector_error_um"],
        "settling_travel_um": r["settling_travel_um"],
        "overshoot_um": r["overshoot_um"],
        "productivity_mm_per_min": r["productivity_mm_per_min"],
    }


def parse_command(text: str) -> Callable[[Controller], None]:
    """A manual-mode command: ``home AXIS``, ``jog AXIS DISTANCE`` (m, relative),
    ``goto X Y`` (m, absolute). Raises ``ConfigError`` naming the command if malformed."""
    words = text.split()
    try:
        if words[0] == "home" and len(words) == 2 and words[1] in AXES:
            return lambda c: c.home(words[1])
        if words[0] == "jog" and len(words) == 3 and words[1] in AXES:
            k, dist = AXES.index(words[1]), float(words[2])

            def jog(c: Controller) -> None:
                target = list(c.position_reference)
                target[k] += dist
                c.jog(target)

            return jog
        if words[0] == "goto" and len(words) == 3:
            target = [float(words[1]), float(words[2])]
            return lambda c: c.jog(target)
    except (IndexError, ValueError):
        pass
    raise ConfigError("commands", f"bad command {text!r}; expected 'home x|y', "
                      "'jog x|y DISTANCE_M' or 'goto X_M Y_M'")
