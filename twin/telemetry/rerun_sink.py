"""Stream a run to rerun: to an ``.rrd`` file (written atomically), a spawned viewer, or a
served gRPC endpoint — or a file and a live viewer at once.

Everything is sent with ``send_columns`` in batches, on one timeline ``sim_time``; nothing is
logged row by row in the cyclic path, so telemetry stays a small share of a run. A run's
spectra go once, at its end, on a timeline of their own (``FREQUENCY``, whole hertz).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from twin.system.jsonio import partial_path
from twin.telemetry.blueprint import PATH_TRANSFORM, PathGrid, default_blueprint, frame_bounds
from twin.telemetry.extent import Extents
from twin.telemetry.sink import PROGRAMMED
from twin.telemetry.spectra import FREQUENCY
from twin.telemetry.viewer import ViewerUnavailable, start_rerun

__all__ = ["APPLICATION_ID", "TIMELINE", "RerunSink"]

APPLICATION_ID = "xy_twin"
TIMELINE = "sim_time"

GATHER_WALL = 2.0
"""Wall seconds of batches a file-only recording gathers into one chunk per entity."""

FLUSH_WALL = 1.0
"""Wall seconds between waits for the recording's writer (``RerunSink._backpressure``)."""

POINT_RADIUS = -1.5
"""Radius of the path's points: 1.5 UI points (negative: screen, not scene, units), so the
path stays visible at any zoom."""

GRID_COLOUR = (215, 215, 215)
"""The path view's grid lines: light grey, under the paths."""

LIVE_FLUSH_TIMEOUT = 5.0
"""Seconds a live viewer may take to accept what was sent before it counts as gone."""

MARKER_SIZE = 6.0
"""Radius of a plot's point markers (UI points), e.g. a spectrum's elastic-mode marker."""

_LEVELS = {"INFO": "INFO", "WARN": "WARN", "ERROR": "ERROR", "DEBUG": "DEBUG"}


class RerunSink:
    """A ``Sink`` backed by a rerun ``RecordingStream``.

    Parameters
    ----------
    path : str or Path or None
        Where to write the ``.rrd``. The file is written to ``<path>.partial`` and renamed
        on ``close()``, so a reader never sees a half-written recording under the final name.
    live : {"spawn", "serve", None}
        Also stream to a spawned native viewer, or to a gRPC server for viewers to connect
        to (``rerun --connect URL``, or the web viewer). Either is a ``rerun`` process of
        its own process group, bound to ``host`` (loopback by default) and ``port``; a port
        something already listens on is refused (``ViewerError``: a stale server would take
        the stream silently). A spawned viewer stays open; a server outlives the run, so a
        viewer can still connect, and ends with this process (or earlier: ``stop_rerun``).
        The live stream is a recording stream of its own beside the file's: a viewer that
        cannot start (no display) or goes away mid-run costs the live view only, with a
        one-line notice, never the file.
    recording_id : str
        Identifies the run; several runs (e.g. one per acceleration law) with distinct ids
        can share one file and are overlaid by the viewer.
    recording_name : str, optional
        Human-readable name shown in the viewer.
    blueprint : bool or rerun.blueprint.Blueprint or callable
        True: the default layout (``default_blueprint``); a callable ``(Extents) ->
        Blueprint``: that layout; either is sent at the start, when the programmed path
        is known and, framed on everything recorded (``extents``), when the recording
        is finished. A Blueprint: that layout, as it is; False: none.
    notice : callable(str), optional
        Told, in one line, when the live view is given up (no display, the viewer exited);
        default: printed on stderr. The notices are kept in ``notices`` as well.
    """

    def __init__(self, path: str | Path | None = None, *, live: str | None = None,
                 recording_id: str = "run", recording_name: str | None = None,
                 blueprint: bool | rrb.Blueprint = True, host: str = "127.0.0.1",
                 port: int = 9876, notice: Callable[[str], None] | None = None):
        if live not in (None, "spawn", "serve"):
            raise ValueError(f"live must be 'spawn', 'serve' or None, got {live!r}")
        if path is None and live is None:
            raise ValueError("RerunSink needs a path, a live viewer, or both")
        self.path = Path(path) if path is not None else None
        self.url: str | None = None
        self.notices: list[str] = []
        self._notice = notice or (lambda text: print(f"warning: {text}", file=sys.stderr))
        self._partial = partial_path(self.path) if self.path else None
        self._rec: rr.RecordingStream | None = None
        self._live: rr.RecordingStream | None = None
        if live is not None:          # first: a refused port leaves no file behind
            self.url = self._start_live(live, host, port)
            if self.url is not None:
                self._live = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
                self._live.set_sinks(rr.GrpcSink(self.url))
        self._closed = self._finished = False
        self.extents = Extents()
        """Ranges of everything sent (values, point bounds, time span)."""
        self._layout = default_blueprint if blueprint is True else (
            blueprint if callable(blueprint) and not isinstance(blueprint, rrb.Blueprint)
            else None)
        self._frame: str | None = None
        try:
            if self._partial is not None:
                self._partial.parent.mkdir(parents=True, exist_ok=True)
                self._rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
                self._rec.set_sinks(rr.FileSink(str(self._partial)))
            for rec in self._streams():
                if recording_name:
                    rec.send_recording_name(recording_name)
                if self._layout is not None:
                    rec.send_blueprint(self._layout(None))
                elif blueprint:
                    rec.send_blueprint(blueprint)
            if blueprint is True:
                self.machine_frame("path")
        except BaseException:   # a Ctrl-C while the file is begun leaves no .partial
            self.discard()
            raise
        self.failed: str | None = None
        """Why the recording could not be written (set by ``finish``), or None."""
        self._flushed = self._sent = time.perf_counter()
        # A file alone gathers the batches into fewer, larger chunks: rerun keeps an index
        # entry per chunk for the file's footer (a few kB each); a live viewer gets each
        # batch at once.
        self._gather = self._live is None
        self._held: dict[str, list[tuple[str, np.ndarray, np.ndarray, np.ndarray | None]]] = {}

    def _start_live(self, live: str, host: str, port: int) -> str | None:
        """Start the live viewer or server; a viewer that cannot start is given up with a
        notice when there is a file to write (``spawn``: no display, the viewer exited),
        and is an error otherwise (a server, or nothing else to keep)."""
        try:
            return start_rerun(live, host=host, port=port)
        except ViewerUnavailable as exc:
            if live != "spawn" or self.path is None:
                raise
            self._tell(f"{exc}; recording to {self.path} only (open it with: twin view "
                       f"{self.path})")
            return None

    def _tell(self, text: str) -> None:
        self.notices.append(text)
        self._notice(text)

    def _streams(self) -> list[rr.RecordingStream]:
        return [rec for rec in (self._rec, self._live) if rec is not None]

    def _lose_live(self, exc: BaseException) -> None:
        """The live viewer went away: the run goes on, recording to the file."""
        live, self._live = self._live, None
        self._gather = True
        with contextlib.suppress(Exception):
            live.disconnect()
        self._tell(f"the live viewer at {self.url} went away ({exc or type(exc).__name__}); "
                   f"recording to {self.path} only")

    # -- Sink protocol ------------------------------------------------------------------
    def machine_frame(self, entity: str) -> None:
        """Draw the 2-D data (mm) under ``entity`` in machine orientation, Y up
        (`PATH_TRANSFORM`), on a grid with a scale bar (``entity/grid``, drawn once the
        first path is known and again, fitted to everything, at the end)."""
        self._frame = entity
        for rec in self._streams():
            rec.log(entity, PATH_TRANSFORM, static=True)

    def static_path(self, entity: str, points: np.ndarray, *,
                    color: tuple[int, int, int] = (160, 160, 160)) -> None:
        """Log a polyline (mm) that does not change with time. The programmed path
        (``.../path/programmed``) also frames the layout's path view and grid on itself."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        self.extents.add_points(entity, pts)
        for rec in self._streams():
            rec.log(entity, rr.LineStrips2D([pts], colors=[color]), static=True)
        if entity.endswith(PROGRAMMED) and len(pts):
            self._send_layout()

    def _send_layout(self) -> None:
        """Draw the path grid fitted to the points recorded so far, and send the layout
        framed on everything recorded so far."""
        frame = frame_bounds(self.extents, f"{self._frame}/**") if self._frame else None
        for rec in self._streams():
            if frame is not None:
                g = PathGrid(*frame)
                base = f"{self._frame}/grid"
                rec.log(f"{base}/lines", rr.LineStrips2D(g.lines, colors=[GRID_COLOUR],
                                                         radii=[-0.5], draw_order=0.0),
                        static=True)
                rec.log(f"{base}/labels", rr.Points2D(
                    g.label_positions, labels=g.labels, show_labels=True, radii=[-0.5],
                    colors=[(90, 90, 90)], draw_order=0.5), static=True)
                rec.log(f"{base}/scale", rr.LineStrips2D(
                    [g.scale], labels=[g.scale_label], show_labels=True, radii=[-1.5],
                    colors=[(60, 60, 60)], draw_order=0.5), static=True)
            if self._layout is not None:
                rec.send_blueprint(self._layout(self.extents))

    def scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Send scalar columns (float64, exact) for samples at times ``t`` (s); a value
        array of shape (n, k) sends k series on one entity."""
        if self.failed is not None:
            return
        self.extents.add_scalars(t, columns)
        if self._gather:
            self._hold("scalars", t, columns)
            return
        self._send_scalars(np.asarray(t, dtype=np.float64), columns)
        self._backpressure()

    def _send_scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        index = [rr.TimeColumn(TIMELINE, duration=t)]
        for rec in self._streams():
            for entity, values in columns.items():
                rec.send_columns(entity, indexes=index,
                                 columns=rr.Scalars.columns(scalars=np.asarray(values)))

    def _send_points(self, t: np.ndarray, columns: Mapping[str, np.ndarray],
                     colors: Mapping[str, np.ndarray] | None = None) -> None:
        index = [rr.TimeColumn(TIMELINE, duration=t)]
        ones = np.ones(len(t), dtype=np.int64)
        for entity, values in columns.items():
            rgb = (colors or {}).get(entity)
            cols = rr.Points2D.columns(positions=np.asarray(values).reshape(-1, 2),
                                       colors=rgb, radii=np.full(len(t), POINT_RADIUS))
            for rec in self._streams():
                rec.send_columns(entity, indexes=index, columns=cols.partition(ones))

    def _hold(self, kind: str, t: np.ndarray, columns: Mapping[str, np.ndarray],
              colors: Mapping[str, np.ndarray] | None = None) -> None:
        t = np.asarray(t, dtype=np.float64)
        for entity, values in columns.items():
            rgb = (colors or {}).get(entity)
            self._held.setdefault(entity, []).append((kind, t, np.asarray(values), rgb))
        if time.perf_counter() - self._sent >= GATHER_WALL:
            self._send_held()

    def _send_held(self) -> None:
        """Send what was gathered: one chunk per entity."""
        self._sent = time.perf_counter()
        held, self._held = self._held, {}
        for entity, parts in held.items():
            t = np.concatenate([p[1] for p in parts])
            values = np.concatenate([p[2] for p in parts])
            if parts[0][0] == "scalars":
                self._send_scalars(t, {entity: values})
            else:
                rgb = (None if any(p[3] is None for p in parts)
                       else np.concatenate([p[3] for p in parts]))
                self._send_points(t, {entity: values}, {entity: rgb})
        self._backpressure()

    def _backpressure(self) -> None:
        """Wait, about once per ``FLUSH_WALL`` seconds, until what was sent is written.

        A run on the twin makes telemetry many times faster than real time; the wait keeps
        rerun's queues from holding more than a second of it, and a writer that has failed
        (a full disk) is found here, mid-run: nothing more is sent, and :meth:`finish` says
        why. (Rerun also keeps an index entry per chunk for the RRD footer that ``rerun rrd
        verify`` requires; a file-only recording gathers its batches, ``GATHER_WALL``, so
        that index stays small: ``bench/memory.py``.)"""
        now = time.perf_counter()
        if now - self._flushed < FLUSH_WALL:
            return
        self._flushed = now
        self._flush()

    def _flush(self) -> None:
        """Wait for the file's writer (a failure fails the recording) and the live stream's
        (a failure loses the live view only)."""
        if self._rec is not None and self.failed is None:
            try:
                self._rec.flush()
            except (RuntimeError, OSError) as exc:
                self._fail(exc)
        if self._live is not None:
            try:
                self._live.flush(timeout_sec=LIVE_FLUSH_TIMEOUT)
            except Exception as exc:
                self._lose_live(exc)

    def points(self, t: np.ndarray, columns: Mapping[str, np.ndarray], *,
               colors: Mapping[str, np.ndarray] | None = None) -> None:
        """Send one 2-D point per sample (mm) for each entity; ``colors``: RGB per point
        (uint8, (n, 3)) for some of them."""
        if self.failed is not None:
            return
        self.extents.add_time(t)
        for entity, values in columns.items():
            self.extents.add_points(entity, values)
        if self._gather:
            self._hold("points", t, columns, colors)
            return
        self._send_points(np.asarray(t, dtype=np.float64), columns, colors)

    def spectrum(self, frequency: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Send scalar columns against frequency (Hz, whole numbers) on the ``FREQUENCY``
        timeline, e.g. a run's spectra at its end (``twin.telemetry.spectra``)."""
        if self.failed is not None or self._finished:
            return
        hz = np.asarray(frequency, dtype=np.int64)
        self.extents.add_spectrum(hz, columns)
        index = [rr.TimeColumn(FREQUENCY, sequence=hz)]
        for rec in self._streams():
            for entity, values in columns.items():
                rec.send_columns(entity, indexes=index, columns=rr.Scalars.columns(
                    scalars=np.asarray(values, dtype=np.float64)))

    def event(self, t: float, text: str, *, level: str = "INFO") -> None:
        """Log a text event on the ``events`` entity at time ``t`` (s)."""
        if self.failed is not None:
            return
        for rec in self._streams():
            rec.set_time(TIMELINE, duration=float(t))
            rec.log("events", rr.TextLog(text, level=_LEVELS.get(level.upper(), "INFO")))

    def style(self, entity: str, *, name: str | list[str],
              color: tuple[int, int, int] | list[tuple[int, int, int]] | None = None,
              marker: str | None = None) -> None:
        """Name (and colour) the scalar series of an entity in the viewer (a list of names,
        and of colours, for an entity that carries several series); with ``marker`` (a
        rerun marker shape: "diamond", "circle" ...) draw them as points, not lines."""
        kwargs: dict = {"names": [name] if isinstance(name, str) else list(name)}
        if color is not None:
            kwargs["colors"] = [color] if isinstance(color, tuple) else list(color)
        style = (rr.SeriesLines(**kwargs) if marker is None else
                 rr.SeriesPoints(**kwargs, markers=[marker] * len(kwargs["names"]),
                                 marker_sizes=[MARKER_SIZE] * len(kwargs["names"])))
        for rec in self._streams():
            rec.log(entity, style, static=True)

    def finish(self) -> None:
        """Flush and complete the file, still under its ``.partial`` name (a run writes its
        summary between this and :meth:`close`).

        A recording that could not be written (a full disk, an I/O error: rerun's file
        writer stops, and the flush reports it) is not an exception here: ``failed`` says
        why, the incomplete ``.partial`` is removed (it holds the space the summary needs)
        and nothing is published."""
        if self._finished:
            return
        self._finished = True
        if self.failed is None:
            self._send_held()
            with contextlib.suppress(RuntimeError, OSError):   # a failing writer: _flush says
                self._send_layout()
            self._flush()
        for rec in self._streams():
            with contextlib.suppress(RuntimeError, OSError):
                rec.disconnect()
        if self.failed is not None and self._partial is not None:
            self._partial.unlink(missing_ok=True)

    def discard(self) -> None:
        """Drop the recording: a run stopped before its loop began (a Ctrl-C while it was
        being set up) has nothing to keep; the ``.partial`` is removed and nothing is
        published."""
        self._finished = self._closed = True
        for rec in self._streams():
            with contextlib.suppress(RuntimeError, OSError):
                rec.disconnect()
        if self._partial is not None:
            self._partial.unlink(missing_ok=True)

    def _fail(self, exc: BaseException) -> None:
        self.failed = str(exc) or type(exc).__name__
        if self._partial is not None:   # rerun says only that its writer stopped
            with contextlib.suppress(OSError):
                fs = os.statvfs(self._partial.parent)
                if fs.f_bavail * fs.f_frsize < 1 << 20:
                    self.failed += "; the file system is full"

    def close(self) -> None:
        """Finish the file and publish it: rename ``.partial`` to the final name (atomic);
        a failed recording is not published."""
        if self._closed:
            return
        self.finish()
        self._closed = True
        if self.failed is None and self._partial is not None and self.path is not None \
                and self._partial.exists():
            os.replace(self._partial, self.path)

    def __enter__(self) -> RerunSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
