"""Stream a run to rerun: to an ``.rrd`` file (written atomically), a spawned viewer, or a
served gRPC endpoint — or a file and a live viewer at once.

Everything is sent with ``send_columns`` in batches, on one timeline ``sim_time``; nothing is
logged row by row in the cyclic path, so telemetry stays a small share of a run.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from twin.processes import stop_process
from twin.telemetry.blueprint import default_blueprint

__all__ = ["APPLICATION_ID", "TIMELINE", "RerunSink", "running_rerun", "start_rerun",
           "stop_rerun"]

APPLICATION_ID = "xy_twin"
TIMELINE = "sim_time"

GATHER_WALL = 2.0
"""Wall seconds of batches a file-only recording gathers into one chunk per entity."""

FLUSH_WALL = 1.0
"""Wall seconds between waits for the recording's writer (``RerunSink._backpressure``)."""

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
        to (``rerun --connect URL``, or the web viewer). Either is a ``rerun`` process bound
        to ``host`` (loopback by default) and ``port``. A spawned viewer stays open; a
        server outlives the run, so a viewer can still connect, and ends with this process
        (or earlier: ``stop_rerun``).
    recording_id : str
        Identifies the run; several runs (e.g. one per acceleration law) with distinct ids
        can share one file and are overlaid by the viewer.
    recording_name : str, optional
        Human-readable name shown in the viewer.
    blueprint : bool or rerun.blueprint.Blueprint
        True: the default layout (path view + error plots); a Blueprint: that layout;
        False: none.
    """

    def __init__(self, path: str | Path | None = None, *, live: str | None = None,
                 recording_id: str = "run", recording_name: str | None = None,
                 blueprint: bool | rrb.Blueprint = True, host: str = "127.0.0.1",
                 port: int = 9876):
        if live not in (None, "spawn", "serve"):
            raise ValueError(f"live must be 'spawn', 'serve' or None, got {live!r}")
        if path is None and live is None:
            raise ValueError("RerunSink needs a path, a live viewer, or both")
        self.path = Path(path) if path is not None else None
        self.url: str | None = None
        self._partial = self.path.with_name(self.path.name + ".partial") if self.path else None
        self._rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        sinks: list = []
        if self._partial is not None:
            self._partial.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(self._partial)))
        if live is not None:
            # A rerun process of our own, bound to loopback: the SDK's serve_grpc and spawn
            # listen on every interface.
            self.url = start_rerun(live, host=host, port=port)
            sinks.append(rr.GrpcSink(self.url))
        if sinks:
            self._rec.set_sinks(*sinks)
        if recording_name:
            self._rec.send_recording_name(recording_name)
        if blueprint is True:
            self._rec.send_blueprint(default_blueprint())
        elif blueprint:
            self._rec.send_blueprint(blueprint)
        self._closed = self._finished = False
        self.failed: str | None = None
        """Why the recording could not be written (set by ``finish``), or None."""
        self._flushed = self._sent = time.perf_counter()
        # A file alone gathers the batches into fewer, larger chunks: rerun keeps an index
        # entry per chunk for the file's footer (a few kB each); a live viewer gets each
        # batch at once.
        self._gather = live is None
        self._held: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}

    # -- Sink protocol ------------------------------------------------------------------
    def static_path(self, entity: str, points: np.ndarray, *,
                    color: tuple[int, int, int] = (160, 160, 160)) -> None:
        """Log a polyline (m) that does not change with time."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        self._rec.log(entity, rr.LineStrips2D([pts], colors=[color]), static=True)

    def scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Send scalar columns (float64, exact) for samples at times ``t`` (s); a value
        array of shape (n, k) sends k series on one entity."""
        if self.failed is not None:
            return
        if self._gather:
            self._hold("scalars", t, columns)
            return
        self._send_scalars(np.asarray(t, dtype=np.float64), columns)
        self._backpressure()

    def _send_scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        index = [rr.TimeColumn(TIMELINE, duration=t)]
        for entity, values in columns.items():
            self._rec.send_columns(entity, indexes=index,
                                   columns=rr.Scalars.columns(scalars=np.asarray(values)))

    def _send_points(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        index = [rr.TimeColumn(TIMELINE, duration=t)]
        ones = np.ones(len(t), dtype=np.int64)
        for entity, values in columns.items():
            cols = rr.Points2D.columns(positions=np.asarray(values).reshape(-1, 2))
            self._rec.send_columns(entity, indexes=index, columns=cols.partition(ones))

    def _hold(self, kind: str, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        t = np.asarray(t, dtype=np.float64)
        for entity, values in columns.items():
            self._held.setdefault(entity, []).append((kind, t, np.asarray(values)))
        if time.perf_counter() - self._sent >= GATHER_WALL:
            self._send_held()

    def _send_held(self) -> None:
        """Send what was gathered: one chunk per entity."""
        self._sent = time.perf_counter()
        held, self._held = self._held, {}
        for entity, parts in held.items():
            t = np.concatenate([p[1] for p in parts])
            values = np.concatenate([p[2] for p in parts])
            send = self._send_scalars if parts[0][0] == "scalars" else self._send_points
            send(t, {entity: values})
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
        try:
            self._rec.flush()
        except (RuntimeError, OSError) as exc:
            self._fail(exc)

    def points(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Send one 2-D point per sample (m) for each entity."""
        if self.failed is not None:
            return
        if self._gather:
            self._hold("points", t, columns)
            return
        self._send_points(np.asarray(t, dtype=np.float64), columns)

    def event(self, t: float, text: str, *, level: str = "INFO") -> None:
        """Log a text event on the ``events`` entity at time ``t`` (s)."""
        if self.failed is not None:
            return
        self._rec.set_time(TIMELINE, duration=float(t))
        self._rec.log("events", rr.TextLog(text, level=_LEVELS.get(level.upper(), "INFO")))

    def style(self, entity: str, *, name: str | list[str],
              color: tuple[int, int, int] | None = None) -> None:
        """Name (and colour) the scalar series of an entity in the viewer's legend (a list of
        names for an entity that carries several series)."""
        kwargs = {"names": [name] if isinstance(name, str) else list(name)}
        if color is not None:
            kwargs["colors"] = [color]
        self._rec.log(entity, rr.SeriesLines(**kwargs), static=True)

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
            try:
                self._rec.flush()
            except (RuntimeError, OSError) as exc:
                self._fail(exc)
        with contextlib.suppress(RuntimeError, OSError):
            self._rec.disconnect()
        if self.failed is not None and self._partial is not None:
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


_PROCESSES: list[subprocess.Popen] = []


def start_rerun(kind: str, *, host: str = "127.0.0.1", port: int = 9876,
                timeout: float = 20.0) -> str:
    """Start ``rerun`` as a viewer (``kind="spawn"``) or a headless gRPC server
    (``"serve"``) listening on ``host:port`` only; return its ``rerun+http`` URL once it
    accepts connections."""
    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    args = [exe, "--bind", host, "--port", str(port)]
    if kind == "serve":
        args.append("--serve-grpc")
    proc = subprocess.Popen(args, env={**os.environ, "RERUN_ANALYTICS": "0"},
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    if kind == "serve":  # a spawned viewer is the user's window: it stays open
        _PROCESSES.append(proc)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"rerun exited with code {proc.returncode} (is port {port} "
                               "in use?)")
        try:
            with socket.create_connection((host, port), timeout=0.2):
                return f"rerun+http://{host}:{port}/proxy"
        except OSError:
            time.sleep(0.05)
    stop_rerun()
    raise RuntimeError(f"rerun did not listen on {host}:{port} within {timeout} s")


def running_rerun() -> list[subprocess.Popen]:
    """The rerun servers this process started that are still running."""
    return [p for p in _PROCESSES if p.poll() is None]


@atexit.register
def stop_rerun() -> None:
    """Stop the rerun servers this process started."""
    for proc in _PROCESSES:
        stop_process(proc, timeout=5.0)
    _PROCESSES.clear()
