"""One run: a program through the controller on a machine (the twin, or real I/O), streamed
to a telemetry sink, summarised into metrics, and written down so it can be repeated.

``run(spec)`` is the main job of the product (``twin run``). It never loses a run: a G-code or
soft-limit error stops before any motion; a trip, a driver fault, a missed-deadline fault or
a stop signal stops the machine safely and still leaves a readable ``.rrd`` and a summary
``.json`` (both written atomically: a reader never sees a half-written file under the final
name). Setting a run up (``RunSpec``, ``prepare``) lives in ``twin.session.setup`` and how it
ends (signals, final status) in ``twin.session.run_end``; this module re-exports the set-up names,
the one place users import a run from.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, machine_identity
from twin.controller.blocks import MotionBlock
from twin.controller.controller import Controller, ControllerStatus
from twin.controller.gcode import Move
from twin.controller.metrics import OscillationMeter
from twin.controller.record import Record
from twin.errors import ConfigError, DeadlineFault, DriverError
from twin.hardware.realtime import DeadlinePolicy, TickStats
from twin.plant import FINE_FIELDS, FINE_WIDTH, TRUTH_FIELDS
from twin.plant.model import mode_periods
from twin.session.loop import TickLoop
from twin.session.record import (
    RunSummary,
    make_sink,
    parse_command,
    recording_path,
    run_summary,
    ticks_dict,
)
from twin.session.run_end import (
    READY,
    RunInterrupted,
    deferred_signals,
    final_status,
    raise_caught,
    signal_name,
    stop_signals,
)
from twin.session.setup import (
    RECORD_CHUNK,
    Prepared,
    RunResult,
    RunSpec,
    axis_models,
    load_program,
    measured_position,
    model_options,
    prepare,
)
from twin.system.jsonio import output_dir, partial_path, record_id, write_json_atomic
from twin.telemetry.channels import TelemetryWriter
from twin.telemetry.sink import Sink
from twin.telemetry.spectra import RunSpectra

__all__ = ["Prepared", "RunResult", "RunSpec", "axis_models", "load_program",
           "measured_position", "model_options", "prepare", "run", "run_summary"]


def run(spec: RunSpec, *, out_dir: str | Path = "runs", rerun: str = "file",
        run_id: str | None = None, sink: Sink | None = None,
        progress: Callable[[float, float], None] | None = None,
        prepared: Prepared | None = None,
        commands: Sequence[Callable[[Controller], None]] = (),
        keep_fine: bool = False, warn: Callable[[str], None] | None = None,
        keep_record: bool = True, rerun_port: int = 9876) -> RunResult:
    """Run ``spec`` and write ``<run_id>.rrd`` and ``<run_id>.json`` into ``out_dir``.

    On the twin (``driver="sim"``) the loop runs in lock-step, as fast as the machine allows;
    behind real I/O it is paced by ``RealTimeLoop`` and the deadline report goes into the
    summary. A driver fault (``DriverError``) or a stop signal (Ctrl-C, SIGTERM, SIGHUP)
    stops the machine (outputs zero, drives disabled) and the run ends ABORTED with its
    record intact; any other error does the same and is then raised. The summary
    (``.json``) is written before the recording gets its final name. A stop signal that
    arrives while the record is written is held until it is complete, then raised as
    ``RunInterrupted`` carrying the result.

    Parameters
    ----------
    spec : RunSpec
    out_dir : path
        Directory for the run record.
    rerun : {"file", "spawn", "serve", "none"} or a path ending in ``.rrd``
        Where the telemetry goes ("file": ``out_dir/<run_id>.rrd``; spawn/serve also write
        that file).
    run_id : str, optional
        Default: time stamp + random suffix.
    sink : Sink, optional
        Use this sink instead of the one ``rerun`` describes (it is closed at the end).
    rerun_port : int
        Port of the live viewer or server (spawn, serve), on 127.0.0.1.
    progress : callable(sim_time, done), optional
        Called a few times a wall-clock second with the simulated time (s) and the share of
        the program done (0 … 1: the programmed path's length up to the block running; for
        manual commands, the commands started; NaN when unknown).
    prepared : Prepared, optional
        An already wired run (``prepare(spec)``), e.g. with a custom controller.
    commands : sequence of callables(controller)
        Manual-mode commands (``controller.home``, ``controller.jog`` ...) started one after
        the other, each when the previous motion has FINISHED; a trip ends the run.
    warn : callable(str), optional
        Live warnings (behind real I/O: deadlines slipping toward the machine's policy,
        ``controller.deadlines``, which stops the run with a FAULT when broken). They go
        into the summary's ``warnings`` and the recording's events as well.
    keep_fine : bool
        Keep the twin's drive-rate samples in ``RunResult.fine`` (they always go to the
        telemetry and into the summary's elastic oscillation; kept, they cost 88 bytes per
        drive interval).
    keep_record : bool
        Keep the whole per-tick record in ``RunResult.record``. Without it (``twin run``)
        the record is released as the telemetry and the running summary consume it, so
        memory does not grow with the run, and ``RunResult.record`` holds only the last
        rows (at most two chunks, ``RECORD_CHUNK`` rows each).
    """
    run_id = run_id or record_id()
    out = output_dir(out_dir)   # before the driver is opened: a bad folder costs nothing
    p = prepared or prepare(spec)
    recording = None
    caught: list[int] = []
    loop: _Loop | None = None
    aborted = fault = None
    late: list[int] = []
    t_wall = time.perf_counter()
    try:
        # one signal handler from the moment the recording is begun: a stop signal before
        # the loop leaves nothing behind (driver closed, no .partial) and is raised; in the
        # loop it takes the one shutdown path (safe stop, record written)
        with stop_signals(caught):
            ours = sink is None         # the sink this run makes (and drops if it stops)
            try:
                pending = [*(parse_command(c) for c in spec.commands), *commands]
                total = len(pending)
                if pending and p.controller.status in READY:
                    # the first command is planned here, as a program is: one the work
                    # zone refuses is refused before anything is written
                    pending.pop(0)(p.controller)
                if ours:
                    sink, recording = make_sink(rerun, out, run_id, notice=warn,
                                                port=rerun_port)
                loop = _Loop(p, sink, spec.time_limit(p.cfg), pending, progress,
                             spec.rt_priority, keep_fine, warn, keep_record, caught, total)
            except BaseException:
                p.driver.close()        # whatever fails once the driver is open closes it
                if ours:
                    _discard(sink, rerun, out, run_id)
                raise
            t_wall = time.perf_counter()
            loop.run_lockstep() if p.plant is not None else loop.run_paced()
    except KeyboardInterrupt as exc:
        if loop is None:
            raise
        aborted = f"interrupted ({signal_name(exc)})"
    except DriverError as exc:
        fault = ("DRIVER", f"driver fault: {exc}")
    except DeadlineFault as exc:
        fault = ("DEADLINE", str(exc))
    except Exception as exc:
        aborted = f"{type(exc).__name__}: {exc}"
        raise
    finally:
        if loop is not None:
            wall = time.perf_counter() - t_wall
            with deferred_signals(late):  # a second signal must not lose the record
                result = loop.finish(spec, run_id, out, recording, wall, aborted, fault)
    if late:
        raise RunInterrupted(result, late[0])
    return result


def _discard(sink: Sink | None, rerun: str, out: Path, run_id: str) -> None:
    """Drop the recording of a run stopped before its loop began: nothing was run, so
    nothing is kept. Without a sink (the signal came while it was being made) its
    ``.partial`` is removed by name."""
    if sink is not None:
        discard = getattr(sink, "discard", None)
        if discard is not None:
            discard()
        return
    with contextlib.suppress(ConfigError, OSError):
        path = recording_path(rerun, out, run_id)
        if path is not None:
            partial_path(path).unlink(missing_ok=True)


class _Loop:
    """The cyclic loop of one run and its records (controller, twin truth, telemetry)."""

    def __init__(self, p: Prepared, sink: Sink, max_time: float,
                 pending: list[Callable[[Controller], None]],
                 progress: Callable[[float, float], None] | None, rt_priority: int = 0,
                 keep_fine: bool = False, warn: Callable[[str], None] | None = None,
                 keep_record: bool = True, caught: list[int] | None = None,
                 commands: int = 0):
        self.p, self.sink, self.pending, self.progress = p, sink, pending, progress
        self.rt_priority = rt_priority
        self.warn = warn
        self.deadline_warnings: list[str] = []
        # stop signals, checked at every telemetry checkpoint
        self.caught: list[int] = caught if caught is not None else []
        self.period = p.cfg.controller.period
        self.max_time = max_time
        self.limit = round(max_time / self.period)
        # Telemetry goes out in batches: every 50 ticks the wall clock is checked and a batch
        # is sent when BATCH_WALL seconds have passed (a few per second for a live viewer,
        # few enough that send overhead stays small).
        self.every = 50
        self._next_batch = time.perf_counter() + BATCH_WALL
        self.truth = (Record(TRUTH_FIELDS, capacity=RECORD_CHUNK) if p.plant is not None
                      else None)
        self.keep_record = keep_record
        self.summary = RunSummary(p.path)   # fed as the telemetry goes out
        lengths = np.array([seg.length for seg in p.path or ()])
        self._reached = np.concatenate(([0.0], np.cumsum(lengths))) / max(lengths.sum(),
                                                                           1e-300)
        self._commands = commands
        periods = mode_periods(p.cfg)        # the model's first elastic mode, per axis
        self.writer = TelemetryWriter(
            sink, p.path, truth_record=self.truth,
            fine_fields=FINE_FIELDS if p.plant is not None else (),
            feeds={item.line: item.feed for item in p.items or ()
                   if isinstance(item, Move | MotionBlock)},
            motor_ratio=[p.cfg.axes[ax].transmission.ratio for ax in AXES],
            contour_tolerance=p.cfg.controller.contour_tolerance,
            spectra=RunSpectra(self.period, p.plant.drive_dt if p.plant is not None else None,
                               modes=[1.0 / period for period in periods])
            if hasattr(sink, "spectrum") else None)       # a sink that records them
        self.names = {int(s): s.name for s in ControllerStatus}
        self.tick_loop: TickLoop | None = None
        # the twin's drive-rate samples: to the telemetry, into the elastic oscillation
        # (streamed: memory does not grow with the run), and kept only when asked
        self.meter = None if p.plant is None else OscillationMeter(
            [max(1, round(period / p.plant.drive_dt)) | 1 for period in periods])
        self.kept: list[np.ndarray] | None = [] if keep_fine and p.plant is not None else None
        self._deflection = [_FINE_COLUMNS["screw_deflection"],
                            _FINE_COLUMNS["screw_deflection"] + 1]
        # the program's events (tool on/off, spindle, coolant, pauses) as the interpolator
        # reaches them: on the recording's event log, counted in the summary
        self.events: dict[str, int] = {}
        p.controller.interpolator.on_event = self._event

    @property
    def ticks(self) -> int:
        """Ticks run so far."""
        return 0 if self.tick_loop is None else self.tick_loop.ticks

    @property
    def stats(self) -> TickStats | None:
        """The paced loop's deadline report (None lock-step or before it ran)."""
        return None if self.tick_loop is None else self.tick_loop.stats

    @property
    def rt_granted(self) -> bool:
        """Whether the paced loop got its SCHED_FIFO priority."""
        return self.tick_loop is not None and self.tick_loop.rt_granted

    def _event(self, t: float, item: Any) -> None:
        kind = getattr(item, "kind", None)
        if kind is None:
            return
        self.events[kind] = self.events.get(kind, 0) + 1
        value = getattr(item, "value", None)
        text = f"line {item.line}: {kind.replace('_', ' ')}"
        if value is not None:
            text += f" {value:g}" if isinstance(value, float) else f" {value}"
        self.sink.event(t, text)

    def drain(self) -> None:
        """Move the twin's drive-rate samples since the last drain to the telemetry, the
        elastic-oscillation meter and (if kept) the run's fine record."""
        if self.meter is None:
            return
        rows = self.p.plant.drain_fine()
        if not len(rows):
            return
        self.meter.feed(rows[:, self._deflection])
        self.writer.add_fine(rows)
        if self.kept is not None:
            self.kept.append(rows)

    def _next_command(self) -> bool:
        """At rest: start the next manual command; False when the run is over."""
        ctrl = self.p.controller
        if not self.pending or ctrl.status not in READY:
            return False
        self.pending.pop(0)(ctrl)
        return True

    def _batch(self) -> bool:
        """Send a telemetry batch if BATCH_WALL has passed since the last; True if sent."""
        now = time.perf_counter()
        if now < self._next_batch:
            return False
        self._next_batch = now + BATCH_WALL
        self._flush()
        if self.progress is not None:
            self.progress(self.ticks * self.period, self._done())
        return True

    def _done(self) -> float:
        """The share of the program done: the path's length to the end of the block
        running (the last one sent); the manual commands started."""
        if self._commands:
            return (self._commands - len(self.pending)) / self._commands
        if len(self._reached) < 2:
            return math.nan
        return float(self._reached[min(max(self.writer.block, 0) + 1,
                                       len(self._reached) - 1)])

    def _flush(self) -> None:
        """Send the rows recorded since the last flush to the telemetry and the running
        summary; release them unless the whole record is kept."""
        record = self.p.controller.record
        sent = self.writer.flush(record, status_names=self.names)
        if sent is not None:
            self.summary.feed(*sent)
        if not self.keep_record:
            record.release(len(record))
            if self.truth is not None:
                self.truth.release(len(record))

    def _checkpoint(self) -> None:
        """Every ``every`` ticks: stop signals, the twin's fine samples, a telemetry batch."""
        raise_caught(self.caught)
        self.drain()
        self._batch()

    def run_lockstep(self) -> None:
        """The twin: as fast as the machine allows; the truth row after every tick."""
        append, row = self.truth.append, self.p.plant.truth_row
        self.tick_loop = TickLoop(self.p.controller, self.p.driver,
                                  after_tick=lambda: append(row()), every=self.every,
                                  checkpoint=self._checkpoint, next_command=self._next_command)
        self.tick_loop.run(self.limit)

    def run_paced(self) -> None:
        """Real I/O: one tick per period of wall time, absolute deadlines. Telemetry goes out
        only in a tick's slack: when the time left before the next deadline exceeds 1.5× the
        last batch's cost (a batch is postponed, never allowed to make a tick late)."""
        clock = time.perf_counter
        cost = [2e-3]  # the last batch's wall time (s): a first guess

        def warning(message: str) -> None:
            self.deadline_warnings.append(message)
            self.sink.event(self.ticks * self.period, message, level="WARN")
            if self.warn is not None:
                self.warn(message)

        def checkpoint() -> None:
            raise_caught(self.caught)
            t0 = clock()
            slack = loop.realtime.start + loop.t + self.period - t0  # type: ignore[union-attr]
            if slack > 1.5 * cost[0] and self._batch():
                cost[0] = clock() - t0

        policy = DeadlinePolicy.from_config(self.p.cfg.controller.deadlines, self.period,
                                            on_warning=warning)
        loop = self.tick_loop = TickLoop(self.p.controller, self.p.driver, every=self.every,
                                         checkpoint=checkpoint,
                                         next_command=self._next_command)
        loop.run_paced(self.period, max_ticks=self.limit, policy=policy,
                       rt_priority=self.rt_priority)

    def finish(self, spec: RunSpec, run_id: str, out: Path, recording: str | None,
               wall: float, aborted: str | None,
               fault: tuple[str, str] | None = None) -> RunResult:
        """Stop the machine, flush the telemetry, write the summary (atomically)."""
        p, ctrl = self.p, self.p.controller
        if self.truth is not None:
            while len(self.truth) < len(ctrl.record):  # interrupted between the appends
                self.truth.append(p.plant.truth_row())
        p.driver.close()
        self.drain()
        self._flush()
        self.writer.finish()            # the spectra of what was run
        # the recording is completed, but published under its final name only after the
        # summary is written: a .rrd never stands without its .json
        finish = getattr(self.sink, "finish", None)
        if finish is not None:
            finish()
        lost = getattr(self.sink, "failed", None)   # the recording could not be written
        if lost is not None:
            recording = None
            if aborted is None and fault is None:
                fault = ("RECORDING", f"the recording could not be written ({lost}); the run "
                         "went on to its end")
        rec = ctrl.record.as_arrays(ctrl.record.first)
        if self.truth is not None:
            rec.update(self.truth.as_arrays(ctrl.record.first))
        # the twin's own clock: with a simulated timer the ticks are not one period apart
        sim_time = p.plant.time if p.plant is not None else self.ticks * self.period
        schedule = getattr(p.driver, "schedule", None)
        stats = self.stats or (schedule.stats() if schedule is not None
                               else TickStats.lockstep(self.period, self.ticks))
        summary: dict[str, Any] = {"run_id": run_id,
                                   **final_status(ctrl.status, aborted, self.max_time,
                                                  fault),
                                   "machine": p.cfg.name,
                                   "controller_model": (p.belief or p.cfg).name,
                                   "driver": spec.driver,
                                   "machine_file": machine_identity(p.cfg),
                                   "controller_model_file": machine_identity(p.belief or p.cfg)}
        if self.summary.samples:    # a run stopped before its first tick has no metrics
            summary.update(self.summary.result())
        if self.events:
            summary["events"] = dict(sorted(self.events.items()))
        if self.meter is not None:
            summary["elastic_oscillation_um"] = self.meter.peak * 1e6
        summary.update({
            "sim_time_s": sim_time,
            "wall_time_s": wall,
            "real_time_factor": sim_time / wall if wall > 0 else math.inf,
            "telemetry_wall_s": self.writer.wall,
            "recording": recording,
            "ticks": {**ticks_dict(stats), "rt_priority_granted": self.rt_granted,
                      "simulated_timer": schedule is not None},
            "spec": spec.to_dict(),
            "config": dataclasses.asdict(p.cfg),
        })
        if p.belief is not None and p.belief is not p.cfg:
            summary["controller_model_config"] = dataclasses.asdict(p.belief)
        if ctrl.error is not None:
            summary["error"] = str(ctrl.error)
        if fault is not None:
            summary["error"] = fault[1]
        warnings = [*getattr(self.sink, "notices", ()), *self.deadline_warnings]
        if warnings:
            summary["warnings"] = warnings
        if p.notes:
            summary["input_warnings"] = list(p.notes)
        if lost is not None:
            summary["recording_error"] = lost
        try:
            write_json_atomic(out / f"{run_id}.json", summary)
        except OSError as exc:   # a full disk: the caller prints it instead
            summary["summary_error"] = f"the summary could not be written: {exc}"
        self.sink.close()
        fine = None
        if self.kept is not None:
            rows = np.concatenate(self.kept) if self.kept else np.zeros((0, FINE_WIDTH))
            fine = {name: rows[:, c:c + w] if w > 1 else rows[:, c]
                    for name, (c, w) in _FINE_SLICES.items()}
        return RunResult(summary, rec, p.path, ctrl.status, p.cfg, fine)


def _fine_slices() -> dict[str, tuple[int, int]]:
    out, col = {}, 0
    for name, width in FINE_FIELDS:
        out[name] = (col, width)
        col += width
    return out


_FINE_SLICES = _fine_slices()
_FINE_COLUMNS = {name: c for name, (c, _) in _FINE_SLICES.items()}
BATCH_WALL = 0.25
"""Wall time between telemetry batches (s)."""
