"""What a run sends to a telemetry sink, and under which entity paths.

``TelemetryWriter`` turns the controller's record and the twin's truth record into batches of
columns (one ``send_columns`` per entity per batch): per axis reference/actual position and
velocity, following error, DAC volts, tacho, armature current, converter voltage, regulator
and DCU terms, screw deflection; the contour error; the programmed and actual paths; events
(block starts, status changes: trips, limit switches).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import numpy as np

from twin.config import AXES
from twin.controller.metrics import contour_error
from twin.controller.record import Record
from twin.controller.regulator import TERMS
from twin.telemetry.sink import Sink

__all__ = ["TelemetryWriter", "programmed_polyline"]

_LEVEL = {"LIMIT_TRIP": "ERROR", "FOLLOWING_ERROR": "ERROR", "INVALID_INPUT": "ERROR",
          "DRIVE_FAULT": "ERROR", "PROGRAM_ERROR": "ERROR", "HOMING_FAILED": "WARN"}


def programmed_polyline(path: Sequence, *, per_metre: float = 2e4, max_points: int = 400
                        ) -> np.ndarray:
    """The programmed path sampled densely enough to draw (m), shape (n, 2)."""
    parts = []
    for seg in path:
        n = int(min(max_points, max(2, seg.length * per_metre)))
        parts.append(seg.point(np.linspace(0.0, seg.length, n)))
    return np.concatenate(parts) if parts else np.zeros((0, 2))


class TelemetryWriter:
    """Batches a run's records into a ``Sink``.

    Parameters
    ----------
    sink : Sink
    path : sequence of Segment
        The programmed path (drawn once; used for the contour error).
    truth_record : Record
        The twin's truth channels (``twin.plant.TRUTH_FIELDS``); None behind real I/O.
    """

    def __init__(self, sink: Sink, path: Sequence, *, truth_record: Record | None = None):
        self.sink = sink
        self.path = list(path)
        self.truth_record = truth_record
        self.wall = 0.0
        """float: wall time spent in telemetry (s)."""
        self._sent = 0
        self._block = -1
        self._status = -1
        t0 = time.perf_counter()
        if self.path:
            sink.static_path("path/programmed", programmed_polyline(self.path))
        style = getattr(sink, "style", None)
        if style is not None:
            for ax in AXES:
                for q in ("position", "velocity"):
                    style(f"axes/{ax}/{q}/reference", name=f"{ax} {q} reference",
                          color=(120, 120, 120))
                    style(f"axes/{ax}/{q}/actual", name=f"{ax} {q} actual",
                          color=(230, 80, 30))
        self.wall += time.perf_counter() - t0

    def flush(self, record: Record, *, status_names: Mapping[int, str] | None = None) -> None:
        """Send the rows appended to ``record`` (and the truth record) since the last flush."""
        n = len(record)
        if n <= self._sent:
            return
        t0 = time.perf_counter()
        c = record.as_arrays(self._sent)
        tr = self.truth_record.as_arrays(self._sent) if self.truth_record is not None else {}
        t = c["t"]
        cols: dict[str, np.ndarray] = {}
        for k, ax in enumerate(AXES):
            base = f"axes/{ax}"
            cols[f"{base}/position/reference"] = c["ref_position"][:, k]
            cols[f"{base}/position/actual"] = c["position"][:, k]
            cols[f"{base}/velocity/reference"] = c["ref_velocity"][:, k]
            cols[f"{base}/following_error_um"] = c["following_error"][:, k] * 1e6
            cols[f"{base}/drive/dac_volts"] = c["dac_volts"][:, k]
            cols[f"{base}/drive/tacho_volts"] = c["tacho_volts"][:, k]
            for j, term in enumerate(TERMS):
                cols[f"{base}/regulator/{term}"] = c["terms"][:, k, j]
            if tr:
                cols[f"{base}/velocity/actual"] = tr["table_velocity"][:, k]
                cols[f"{base}/drive/armature_current"] = tr["armature_current"][:, k]
                cols[f"{base}/drive/converter_voltage"] = tr["converter_voltage"][:, k]
                cols[f"{base}/screw_deflection_um"] = tr["screw_deflection"][:, k] * 1e6
        if self.path:
            # Live view: search 3 blocks either side of the active one (exact unless the
            # table lags further behind; the run summary searches the whole path).
            hint = np.clip(c["block"], 0, len(self.path) - 1)
            cols["errors/contour_um"] = contour_error(self.path, c["position"], hint=hint,
                                                      window=3) * 1e6
        self.sink.scalars(t, cols)
        self.sink.points(t, {"path/actual": c["position"], "path/reference": c["ref_position"]})
        self._events(t, c, status_names or {})
        self._sent = n
        self.wall += time.perf_counter() - t0

    def _events(self, t: np.ndarray, c: Mapping[str, np.ndarray],
                names: Mapping[int, str]) -> None:
        block, line, status = c["block"], c["line"], c["status"]
        prev_b = np.concatenate(([self._block], block[:-1]))
        for i in np.flatnonzero(block != prev_b):
            if block[i] >= 0:
                where = f" (line {line[i]})" if line[i] > 0 else ""
                self.sink.event(float(t[i]), f"block {block[i]}{where} starts")
        self._block = int(block[-1])
        prev_s = np.concatenate(([self._status], status[:-1]))
        for i in np.flatnonzero(status != prev_s):
            name = names.get(int(status[i]), str(int(status[i])))
            self.sink.event(float(t[i]), f"controller {name}", level=_LEVEL.get(name, "INFO"))
        self._status = int(status[-1])
