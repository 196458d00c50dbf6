"""What a run sends to a telemetry sink, under which entity paths, in which units.

``TelemetryWriter`` turns the controller's record, the twin's truth record and the twin's
drive-rate samples into batches of columns (one ``send_columns`` per entity per batch): per
axis reference/actual position and velocity, following error, DAC volts, tacho, regulator
and DCU terms (once per controller period); armature current, converter voltage, conduction
and screw deflection (once per drive interval: the converter's pulses and the screw's
ringing lie above the controller's Nyquist rate); the contour error; the programmed and
actual paths; events (block starts, status changes: trips, limit switches); at the end, the
spectra of the following error and the screw deflection (``twin.telemetry.spectra``). The
live contour error is measured against the path densified to chords within 1 nm
(``PathDistance``); the run summary's is exact.

A recording holds the units an engineer reads (``SERIES`` names each entity's): positions
and paths in mm, velocities and feeds in mm/min, errors and the screw deflection in µm,
volts, amperes and the motor speed in rpm. This is the edge where SI becomes them
(``to_shown``); nothing else converts.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence

import numpy as np

from twin.config import AXES
from twin.controller.record import Record
from twin.telemetry.sink import PROGRAMMED, Sink
from twin.telemetry.spectra import RunSpectra
from twin.units import MM, MM_PER_MIN, RPM, UM

__all__ = ["COLOURS", "SERIES", "PathDistance", "TelemetryWriter", "error_colors",
           "programmed_polyline", "series_for", "style_series", "to_shown"]

COLOURS = {"grey": (120, 120, 120), "orange": (245, 125, 20), "blue": (40, 120, 220),
           "green": (40, 160, 60), "purple": (148, 103, 189), "brown": (140, 86, 75),
           "red": (214, 39, 40), "teal": (23, 160, 170)}
"""The colours of the recorded series, by the name the layout's titles use for them."""

AXIS_COLOURS = {"x": "orange", "y": "blue"}
"""The colour of each axis where one plot shows both (the spectra)."""

SERIES: dict[str, tuple[str, tuple[tuple[str, str], ...]]] = {
    "axes/{a}/position/reference": ("mm", (("reference", "grey"),)),
    "axes/{a}/position/actual": ("mm", (("actual", "orange"),)),
    "axes/{a}/velocity/reference": ("mm/min", (("reference", "grey"),)),
    "axes/{a}/velocity/actual": ("mm/min", (("actual", "orange"),)),
    "axes/{a}/following_error_um": ("µm", (("following error", "orange"),)),
    "axes/{a}/regulator": ("V", tuple(zip(("p", "i", "d", "FF", "DCU"),
                                          ("blue", "green", "brown", "orange", "purple"),
                                          strict=True))),
    "axes/{a}/drive/dac_volts": ("V", (("DAC", "blue"),)),
    "axes/{a}/drive/tacho_volts": ("V", (("tacho", "orange"),)),
    "axes/{a}/drive/converter_voltage": ("V", (("converter voltage", "purple"),)),
    "axes/{a}/drive/armature_current": ("A", (("armature current", "red"),)),
    "axes/{a}/drive/motor_speed": ("rpm", (("motor speed", "blue"),)),
    "axes/{a}/drive/conduction": ("1", (("conduction", "green"),)),
    "axes/{a}/screw_deflection_um": ("µm", (("screw deflection", "brown"),)),
    "errors/contour_um": ("µm", (("contour error", "red"),)),
    "feed/programmed": ("mm/min", (("programmed F", "grey"),)),
    "feed/commanded": ("mm/min", (("commanded", "blue"),)),
    "feed/actual": ("mm/min", (("actual", "orange"),)),
}
"""Every scalar entity a run records (``{a}``: the axis): its unit, and the name and colour
of each of its series (the regulator carries one series per term, in
``twin.controller.regulator.TERMS`` order)."""

_SHOWN = {"mm": 1.0 / MM, "mm/min": 1.0 / MM_PER_MIN, "µm": 1.0 / UM, "rpm": 1.0 / RPM,
          "V": 1.0, "A": 1.0, "1": 1.0}


def series_for(entity: str) -> tuple[str, tuple[tuple[str, str], ...]] | None:
    """``SERIES``' entry of a concrete entity (``axes/x/position/actual``), or None."""
    for pattern, entry in SERIES.items():
        if any(pattern.format(a=ax) == entity for ax in AXES):
            return entry
    return None


def style_series(sink: Sink, entities: Sequence[str]) -> None:
    """Name and colour the series of ``entities`` (``SERIES``) in the sink's legend, when the
    sink has one (``style``): ``x position actual``, orange."""
    style = getattr(sink, "style", None)
    if style is None:
        return
    for entity in entities:
        entry = series_for(entity)
        if entry is None:
            continue
        parts = entity.split("/")
        axis = f"{parts[1]} " if parts[0] == "axes" else ""
        style(entity, name=[axis + name for name, _ in entry[1]],
              color=[COLOURS[colour] for _, colour in entry[1]])


def to_shown(unit: str, values: np.ndarray) -> np.ndarray:
    """SI values (m, m/s, rad/s, V, A, 1) in the recorded ``unit`` (a ``SERIES`` unit)."""
    return np.asarray(values, dtype=np.float64) * _SHOWN[unit]


_GREEN, _YELLOW, _RED = (np.array(c, dtype=np.float64) for c in
                         ((40, 180, 60), (240, 200, 30), (220, 40, 40)))


def error_colors(ratio: np.ndarray) -> np.ndarray:
    """RGB (uint8, shape (n, 3)) of contour errors as multiples of the tolerance: green at
    0, yellow at 1, red from 2 on (linear between)."""
    r = np.clip(np.asarray(ratio, dtype=np.float64), 0.0, 2.0)[:, None]
    low = _GREEN + (_YELLOW - _GREEN) * np.minimum(r, 1.0)
    rgb = np.where(r <= 1.0, low, _YELLOW + (_RED - _YELLOW) * (r - 1.0))
    return np.rint(rgb).astype(np.uint8)

_LEVEL = {"LIMIT_TRIP": "ERROR", "FOLLOWING_ERROR": "ERROR", "INVALID_INPUT": "ERROR",
          "DRIVE_FAULT": "ERROR", "PROGRAM_ERROR": "ERROR", "HOMING_FAILED": "WARN"}


class PathDistance:
    """Distance (m) from points to the programmed path, for the live view.

    The path is replaced by chords of one length L, short enough that their sagitta (the
    largest gap between a chord and the curve, L²·κ/8) is at most ``sagitta`` on the most
    curved segment (L ≤ ``max_chord``; relaxed, with ``sagitta`` updated, if the path would
    need more than ``max_vertices``). A point's distance is the exact distance to the nearest
    chord: that chord has an end within (distance to the nearest vertex + L) of the point,
    so the ``k`` nearest vertices suffice unless the ``k``-th is still inside that radius,
    when a ball query is made (rare: only where the path comes back near itself). The result
    is within ``sagitta`` of the exact contour error, and two orders of magnitude cheaper than
    the exact spline distance, which the run summary uses.
    """

    def __init__(self, path: Sequence, *, sagitta: float = 1e-8, max_chord: float = 2e-4,
                 k: int = 6, max_vertices: int = 500_000):
        from scipy.spatial import cKDTree

        grid = np.linspace(0.0, 1.0, 257)
        kappa = max((float(np.max(np.abs(seg.curvature(grid * seg.length)))) for seg in path),
                    default=0.0)
        chord = min(max_chord, math.sqrt(8.0 * sagitta / kappa) if kappa > 0 else max_chord)
        total = sum(seg.length for seg in path)
        chord = max(chord, total / max_vertices)
        self.sagitta = chord * chord * kappa / 8.0
        """float: the largest gap between the chords and the path (m)."""
        pts = [np.asarray(path[0].start, dtype=float)[None]] if path else []
        for seg in path:
            n = max(math.ceil(seg.length / chord), 1)
            pts.append(seg.point(np.linspace(0.0, seg.length, n + 1))[1:])
        self.vertices = np.concatenate(pts) if pts else np.zeros((1, 2))
        self._tree = cKDTree(self.vertices)
        self._k = min(k, len(self.vertices))
        self._chord = chord
        # chord j runs from vertex j to j + 1 (a lone vertex: one chord of zero length)
        v = self.vertices
        self._a = v[:-1] if len(v) > 1 else v
        self._d = v[1:] - v[:-1] if len(v) > 1 else np.zeros_like(v)
        den = np.einsum("ij,ij->i", self._d, self._d)
        self._inv_len2 = np.divide(1.0, den, out=np.zeros_like(den), where=den > 0)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Distances (m) of points (n, 2).

        The nearest chord has an end within (distance to the nearest vertex + the longest
        chord) of the point: the ``k`` nearest vertices are tried, and a point whose ``k``-th
        neighbour is still inside that radius gets a ball query instead (exact, rare)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        dist, idx = self._tree.query(points, k=self._k)
        dist, idx = dist.reshape(len(points), -1), idx.reshape(len(points), -1)
        best = self._to_chords(points, idx)
        short = np.flatnonzero(dist[:, -1] < dist[:, 0] + self._chord)
        for i in short if self._k < len(self.vertices) else ():
            ball = self._tree.query_ball_point(points[i], dist[i, 0] + self._chord)
            best[i] = self._to_chords(points[i:i + 1], np.array([ball]))[0]
        return best

    def _to_chords(self, points: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Distance of each point to the nearest of the chords that end at its vertices
        ``idx`` (n, m): chords idx − 1 and idx, in one pass."""
        j = np.concatenate((idx - 1, idx), axis=1)
        np.clip(j, 0, len(self._a) - 1, out=j)
        d = self._d[j]
        q = points[:, None, :] - self._a[j]
        t = np.einsum("nkj,nkj->nk", q, d) * self._inv_len2[j]
        np.clip(t, 0.0, 1.0, out=t)
        q -= t[..., None] * d
        return np.sqrt(np.einsum("nkj,nkj->nk", q, q).min(axis=1))


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
    fine_fields : sequence of (str, int)
        Layout of the twin's drive-rate sample rows (``twin.plant.FINE_FIELDS``) that
        :meth:`add_fine` receives.
    feeds : mapping of int to float or None
        Programmed feed (m/s; None for a rapid) by source line, for the feed view's
        programmed F (a line run several times with different feeds shows its last).
    motor_ratio : sequence of float, optional
        Table metres per motor radian, per axis (``TransmissionConfig.ratio``): the motor
        speed (rad/s) in the drive view is the twin's table velocity over it.
    contour_tolerance : float
        Contour tolerance (m): the colour scale of the actual path (green at 0, yellow at
        the tolerance, red from twice it).
    spectra : RunSpectra, optional
        Fed with the following error and the screw deflection as they are sent;
        :meth:`finish` sends the spectra.
    """

    def __init__(self, sink: Sink, path: Sequence, *, truth_record: Record | None = None,
                 fine_fields: Sequence[tuple[str, int]] = (),
                 feeds: Mapping[int, float | None] | None = None,
                 motor_ratio: Sequence[float] | None = None,
                 contour_tolerance: float = 20e-6, spectra: RunSpectra | None = None):
        self.sink = sink
        self.spectra = spectra
        self.feeds = dict(feeds or {})
        self.motor_ratio = None if motor_ratio is None else np.asarray(motor_ratio, float)
        self.contour_tolerance = contour_tolerance
        self.path = list(path)
        self.truth_record = truth_record
        self.wall = 0.0
        """float: wall time spent in telemetry (s)."""
        self._sent = 0
        self._block = -1
        self.block = -1
        """int: the block of the last row sent (-1 before any)."""
        self._status = -1
        self._fine: list[np.ndarray] = []
        self._col: dict[str, int] = {}
        col = 0
        for name, width in fine_fields:
            self._col[name] = col
            col += width
        t0 = time.perf_counter()
        if self.path:
            sink.static_path(PROGRAMMED, to_shown("mm", programmed_polyline(self.path)))
            self._distance = PathDistance(self.path)
        # styles only for series that will carry data: the actual velocity, the motor
        # speed and the actual feed come from the twin's truth, the drive-rate channels
        # from its samples, the programmed feed from the program's lines
        truth = truth_record is not None
        sent = ["feed/commanded", *(["feed/actual"] if truth else []),
                *(["feed/programmed"] if self.feeds else []),
                *(["errors/contour_um"] if self.path else [])]
        for ax in AXES:
            base = f"axes/{ax}"
            sent += [f"{base}/{q}" for q in ("position/reference", "position/actual",
                                             "velocity/reference", "following_error_um",
                                             "regulator", "drive/dac_volts",
                                             "drive/tacho_volts")]
            if truth:
                sent.append(f"{base}/velocity/actual")
                if self.motor_ratio is not None:
                    sent.append(f"{base}/drive/motor_speed")
            if self._col:
                sent += [f"{base}/{q}" for q in ("drive/armature_current",
                                                 "drive/converter_voltage",
                                                 "drive/conduction", "screw_deflection_um")]
        style_series(sink, sent)
        self.wall += time.perf_counter() - t0

    def add_fine(self, rows: np.ndarray) -> None:
        """Queue drive-rate samples of the twin (rows of ``twin.plant.FINE_FIELDS``) for the
        next flush."""
        self._fine.append(rows)

    def _flush_fine(self) -> None:
        if not self._fine:
            return
        rows = np.concatenate(self._fine)
        self._fine.clear()
        c = self._col
        cols: dict[str, np.ndarray] = {}
        for k, ax in enumerate(AXES):
            base = f"axes/{ax}"
            cols[f"{base}/drive/armature_current"] = rows[:, c["armature_current"] + k]
            cols[f"{base}/drive/converter_voltage"] = rows[:, c["converter_voltage"] + k]
            cols[f"{base}/drive/conduction"] = rows[:, c["conduction"] + k]
            cols[f"{base}/screw_deflection_um"] = to_shown("µm",
                                                          rows[:, c["screw_deflection"] + k])
        self.sink.scalars(rows[:, c["t"]], cols)
        if self.spectra is not None:
            d = c["screw_deflection"]
            self.spectra.feed("screw_deflection", rows[:, d:d + len(AXES)])

    def flush(self, record: Record, *, status_names: Mapping[int, str] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray] | None] | None:
        """Send the rows appended to ``record`` (and the truth record) since the last flush,
        and the queued drive-rate samples. Returns the rows sent, ``(controller columns,
        truth columns or None)``, for another consumer of the same rows (the run's running
        summary); None if there were none."""
        n = len(record)
        t0 = time.perf_counter()
        self._flush_fine()
        if n <= self._sent:
            self.wall += time.perf_counter() - t0
            return None
        c = record.as_arrays(self._sent)
        tr = self.truth_record.as_arrays(self._sent) if self.truth_record is not None else {}
        t = c["t"]
        cols: dict[str, np.ndarray] = {}
        for k, ax in enumerate(AXES):
            base = f"axes/{ax}"
            cols[f"{base}/position/reference"] = to_shown("mm", c["ref_position"][:, k])
            cols[f"{base}/position/actual"] = to_shown("mm", c["position"][:, k])
            cols[f"{base}/velocity/reference"] = to_shown("mm/min", c["ref_velocity"][:, k])
            cols[f"{base}/following_error_um"] = to_shown("µm", c["following_error"][:, k])
            cols[f"{base}/drive/dac_volts"] = c["dac_volts"][:, k]
            cols[f"{base}/drive/tacho_volts"] = c["tacho_volts"][:, k]
            cols[f"{base}/regulator"] = c["terms"][:, k, :]   # one series per term
            if tr:
                cols[f"{base}/velocity/actual"] = to_shown("mm/min", tr["table_velocity"][:, k])
                if self.motor_ratio is not None:
                    cols[f"{base}/drive/motor_speed"] = to_shown(
                        "rpm", tr["table_velocity"][:, k] / self.motor_ratio[k])
        cols.update(self._feed_columns(c, tr))
        if self.spectra is not None:
            self.spectra.feed("following_error", c["following_error"])
        colors = None
        if self.path:
            contour = self._distance(c["position"])
            cols["errors/contour_um"] = to_shown("µm", contour)
            colors = error_colors(contour / self.contour_tolerance)
        self.sink.scalars(t, cols)
        self.sink.points(t, {"path/actual": to_shown("mm", c["position"]),
                             "path/reference": to_shown("mm", c["ref_position"])},
                         colors={"path/actual": colors} if colors is not None else None)
        self._events(t, c, status_names or {})
        self._sent = n
        self.wall += time.perf_counter() - t0
        return c, (tr or None)

    def finish(self) -> None:
        """Send the run's spectra (after the last :meth:`flush`; ``RunSpectra.send``), x
        and y in their colours."""
        if self.spectra is not None:
            t0 = time.perf_counter()
            self.spectra.send(self.sink, colours={a: COLOURS[AXIS_COLOURS[a]] for a in AXES})
            self.wall += time.perf_counter() - t0

    def _feed_columns(self, c: Mapping[str, np.ndarray], tr: Mapping[str, np.ndarray]
                      ) -> dict[str, np.ndarray]:
        """Feed (mm/min): programmed F of the tick's source line (NaN for a rapid or no
        motion), commanded |v_ref| and, on the twin, the table's actual |v|."""
        cols = {"feed/commanded": to_shown("mm/min", np.hypot(*c["ref_velocity"].T))}
        if tr:
            cols["feed/actual"] = to_shown("mm/min", np.hypot(*tr["table_velocity"].T))
        if self.feeds:
            lines = c["line"].ravel()
            programmed = np.full(len(lines), np.nan)
            for line in np.unique(lines):
                feed = self.feeds.get(int(line))
                if feed is not None:
                    programmed[lines == line] = feed / MM_PER_MIN
            cols["feed/programmed"] = programmed
        return cols

    def _events(self, t: np.ndarray, c: Mapping[str, np.ndarray],
                names: Mapping[int, str]) -> None:
        block, line, status = c["block"], c["line"], c["status"]
        prev_b = np.concatenate(([self._block], block[:-1]))
        for i in np.flatnonzero(block != prev_b):
            if block[i] >= 0:
                where = f" (line {line[i]})" if line[i] > 0 else ""
                self.sink.event(float(t[i]), f"block {block[i]}{where} starts")
        self._block = self.block = int(block[-1])
        prev_s = np.concatenate(([self._status], status[:-1]))
        for i in np.flatnonzero(status != prev_s):
            name = names.get(int(status[i]), str(int(status[i])))
            self.sink.event(float(t[i]), f"controller {name}", level=_LEVEL.get(name, "INFO"))
        self._status = int(status[-1])
