"""The parts of a run record: the metric summary, the telemetry sink a ``--rerun`` option
names, the deadline report, and manual-mode commands (the files themselves are written by
``twin.system.jsonio``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES
from twin.controller.controller import Controller
from twin.controller.summary import RunningSummary
from twin.errors import ConfigError
from twin.hardware.realtime import TickStats
from twin.telemetry.sink import NullSink, Sink

__all__ = ["RunSummary", "make_sink", "parse_command", "recording_path", "run_summary",
           "ticks_dict"]


def make_sink(rerun: str, out: Path, run_id: str,
              notice: Callable[[str], None] | None = None,
              port: int = 9876, blueprint: Any = True) -> tuple[Sink, str | None]:
    """The sink ``--rerun`` names: spawn, serve, none, file (``out/<run_id>.rrd``) or a path
    ending in ``.rrd``; spawn and serve also write the file. Returns (sink, .rrd path).
    ``notice`` is told when the live view is given up (``RerunSink``); ``port`` is the live
    viewer's or server's; ``blueprint`` the layout (``RerunSink``'s; default a run's)."""
    path = recording_path(rerun, out, run_id)
    if path is None:
        return NullSink(), None
    from twin.telemetry.rerun_sink import RerunSink

    live = rerun if rerun in ("spawn", "serve") else None
    return RerunSink(path, live=live, recording_id=run_id, recording_name=run_id,
                     notice=notice, port=port, blueprint=blueprint), str(path)


def recording_path(rerun: str, out: Path, run_id: str) -> Path | None:
    """Where ``--rerun`` puts the ``.rrd`` (None: no file)."""
    if rerun == "none":
        return None
    if rerun.endswith(".rrd"):
        return Path(rerun)
    if rerun in ("file", "spawn", "serve"):
        return out / f"{run_id}.rrd"
    raise ConfigError("rerun", f"must be spawn, serve, none, file or a path ending in "
                      f".rrd, got {rerun!r}")


def ticks_dict(stats: TickStats) -> dict[str, Any]:
    """The deadline report as the summary's ``ticks`` object."""
    d = stats.to_dict()
    return {k: d[k] for k in ("due", "on_time", "late", "skipped", "jitter_p50_us",
                              "jitter_p99_us", "jitter_max_us", "on_time_ratio", "paced")}


SUMMARY_BLOCK = 16384
"""Samples a run's summary measures at a time (82 s at 200 Hz): a few MB, and a program of
many segments searched once per block."""


class RunSummary:
    """The metric part of a run's summary (µm, mm, s), fed with the record as it grows, in
    memory that does not grow with the run (:class:`RunningSummary`).

    The actual velocity is the twin's table velocity when the record has it (a simulated
    run), else the derivative of the measured position (real I/O): numpy's second-order
    central difference on uneven times, one-sided at the ends, computed across the feeds
    (each sample waits for the next one)."""

    def __init__(self, path: list):
        # No active-block hint: a table lagging several short blocks behind its reference
        # would be measured against the wrong ones. The exact search over the path is cheap.
        self._running = RunningSummary(path, block=SUMMARY_BLOCK) if path else None
        self.samples = 0
        self._held: dict[str, np.ndarray] | None = None   # samples waiting for a derivative
        self._edge = True                                  # the first sample is not out yet
        # without a program (home, jog): when the reference moved, and how far
        self._moved: list[float] = []                      # [first, last] moving time (s)
        self._travel = 0.0                                 # reference travel (m)
        self._last_ref: np.ndarray | None = None

    def feed(self, rec: Mapping[str, np.ndarray],
             truth: Mapping[str, np.ndarray] | None = None) -> None:
        """Add the rows of a controller record (``t``, ``ref_position``, ``ref_velocity``,
        ``position``) and of the twin's truth record (``table_velocity``) if there is one."""
        n = len(rec["t"])
        self.samples += n
        if n == 0:
            return
        if self._running is None:
            self._manual(rec)
            return
        cols = {k: np.asarray(rec[k], dtype=float)
                for k in ("t", "ref_position", "ref_velocity", "position")}
        velocity = truth.get("table_velocity") if truth is not None else None
        if velocity is not None:
            self._running.feed(*cols.values(), velocity)
            return
        if self._held is not None:
            cols = {k: np.concatenate((self._held[k], v)) for k, v in cols.items()}
        t, pos = cols["t"], cols["position"]
        if len(t) < 2:
            self._held = cols
            return
        h1, h2 = np.diff(t)[:-1, None], np.diff(t)[1:, None]
        inner = (-h2 / (h1 * (h1 + h2)) * pos[:-2] + (h2 - h1) / (h1 * h2) * pos[1:-1]
                 + h1 / (h2 * (h1 + h2)) * pos[2:])       # samples 1 … L−2 of the window
        if self._edge:                                     # the first sample: forward
            d = np.concatenate((((pos[1] - pos[0]) / (t[1] - t[0]))[None, :], inner))
            out = slice(0, len(t) - 1)
        else:                                              # sample 0 went out last time
            d, out = inner, slice(1, len(t) - 1)
        self._running.feed(t[out], cols["ref_position"][out], cols["ref_velocity"][out],
                           pos[out], d)
        self._edge = False
        self._held = {k: v[-2:] for k, v in cols.items()}

    def _manual(self, rec: Mapping[str, np.ndarray]) -> None:
        """Manual commands have no programmed path: note when the reference moved and how
        far it went."""
        t = np.asarray(rec["t"], dtype=float)
        ref = np.asarray(rec["ref_position"], dtype=float)
        moving = np.flatnonzero(np.any(np.asarray(rec["ref_velocity"]) != 0.0, axis=1))
        if len(moving):
            if not self._moved:
                self._moved = [float(t[moving[0]]), float(t[moving[-1]])]
            self._moved[1] = float(t[moving[-1]])
        joined = ref if self._last_ref is None else np.vstack((self._last_ref, ref))
        self._travel += float(np.sum(np.hypot(*np.diff(joined, axis=0).T)))
        self._last_ref = ref[-1:].copy()

    def result(self) -> dict[str, Any]:
        """The summary's metric keys. Without a programmed path (manual commands: home,
        jog) the cycle time is the time the reference moved and the path length how far
        it went; the contour metrics need a path and are left out."""
        if self._running is None:
            return {"cycle_time_s": self._moved[1] - self._moved[0] if self._moved else 0.0,
                    "path_length_mm": self._travel * 1e3}
        if self.samples < 2:
            return {"cycle_time_s": 0.0, "path_length_mm": 0.0}
        if self._held is not None and not self._edge:       # the last sample: backward
            h = self._held
            d = (h["position"][-1] - h["position"][-2]) / (h["t"][-1] - h["t"][-2])
            self._running.feed(h["t"][-1:], h["ref_position"][-1:], h["ref_velocity"][-1:],
                               h["position"][-1:], d[None, :])
            self._held = None
        m = self._running.result()
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


def run_summary(rec: Mapping[str, np.ndarray], path: list) -> dict[str, Any]:
    """The metric part of the summary (µm, mm, s) from a whole run's record (controller and
    truth columns in one mapping; see :class:`RunSummary`)."""
    summary = RunSummary(path)
    summary.feed(rec, rec)
    return summary.result()


def parse_command(text: str) -> Callable[[Controller], None]:
    """A manual-mode command: ``home AXIS``, ``jog AXIS DISTANCE`` (relative) or ``goto X
    Y`` (absolute), the lengths in metres, or in millimetres with a trailing ``mm``
    (``jog x 10 mm``, ``goto 50 20 mm``: what a person reads in the run record). Raises
    ``ConfigError`` naming the command if malformed."""
    words = text.split()
    scale = 1.0
    if len(words) > 1 and words[-1] == "mm":
        words, scale = words[:-1], 1e-3
    try:
        if words[0] == "home" and len(words) == 2 and words[1] in AXES and scale == 1.0:
            return lambda c: c.home(words[1])
        if words[0] == "jog" and len(words) == 3 and words[1] in AXES:
            k, dist = AXES.index(words[1]), float(words[2]) * scale

            def jog(c: Controller) -> None:
                target = list(c.position_reference)
                target[k] += dist
                c.jog(target)

            return jog
        if words[0] == "goto" and len(words) == 3:
            target = [float(words[1]) * scale, float(words[2]) * scale]
            return lambda c: c.jog(target)
    except (IndexError, ValueError):
        pass
    raise ConfigError("commands", f"bad command {text!r}; expected 'home x|y', "
                      "'jog x|y DISTANCE mm' or 'goto X Y mm' (without mm: metres)")
