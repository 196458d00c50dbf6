"""One run: a program through the controller on a machine (the twin, or real I/O), streamed
to a telemetry sink, summarised into metrics, and written down so it can be repeated.

``run(spec)`` is the main job of the product (``twin run``). It never loses a run: a G-code or
soft-limit error stops before any motion; a trip, a driver fault or Ctrl-C stops the machine
safely and still leaves a readable ``.rrd`` and a summary ``.json`` (both written
atomically: a reader never sees a half-written file under the final name).
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import math
import signal
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig, load_machine, machine_identity
from twin.controller.controller import Controller, ControllerStatus
from twin.controller.gcode import decode_program, parse
from twin.controller.library import build_program, program_path
from twin.controller.linear import LinearAxisModel
from twin.controller.metrics import OscillationMeter
from twin.controller.record import Record
from twin.drive.linear import axis_transfer_function
from twin.errors import ConfigError, DeadlineFault, DriverError
from twin.hardware.realtime import DeadlinePolicy, RealTimeLoop, TickStats, fifo_priority
from twin.hardware.sim import SimDriver
from twin.jsonio import output_dir
from twin.model import mode_periods
from twin.plant import FINE_FIELDS, FINE_WIDTH, TRUTH_FIELDS, Plant
from twin.runrecord import (
    make_sink,
    parse_command,
    run_summary,
    ticks_dict,
    write_json_atomic,
)
from twin.telemetry.channels import TelemetryWriter
from twin.telemetry.sink import Sink

__all__ = ["STOP_SIGNALS", "Prepared", "RunInterrupted", "RunResult", "RunSpec", "Terminated",
           "axis_models", "final_status", "load_program", "measured_position",
           "model_options", "prepare", "run", "run_summary", "write_json_atomic"]


@dataclass(frozen=True)
class RunSpec:
    """Everything that determines a run (saved in the run's JSON, so it can be repeated).

    Attributes
    ----------
    machine : str
        Preset name or TOML path: the plant (the physics the twin runs), and the machine's
        controller settings and I/O.
    controller_model : str or None
        Preset name or TOML path of the machine *as the controller believes it to be*: every
        model-based setting (position gain, DCU α1..α3, feed-forward, corner model, speed-loop
        model) is derived from its axes. None: the machine itself. ``overrides`` do not apply
        to it (they are the plant's and the controller's settings).
    program : str or None
        G-code file; None runs the built-in program ``builtin``.
    builtin : str
        Built-in program name (``twin.controller.library.PROGRAMS``).
    profile, planner : str or None
        Acceleration law and planner mode; None: the machine's settings.
    dcu_order : int or None
        0 … 3; None: the machine's setting.
    period : float or None
        Controller period (s); None: the machine's.
    overrides : mapping
        ``--set`` values by dotted config path (see ``twin.overrides``).
    mode : str
        Interpolator interface: "extended" (float v/a/j channels) or "traditional".
    dry_run : bool
        Run the controller without driving the motors.
    max_time : float
        Stop after this much controller time (s).
    start : (float, float) or None
        Table position at the start (m); None: the home keyframe.
    commands : tuple of str
        Manual mode instead of a program (``builtin="none"``): ``"home x"``, ``"jog x 0.01"``
        (relative, m), ``"goto 0.05 0.02"`` (absolute, m), run one after the other.
    driver : str
        ``"sim"``: the twin in lock-step; or a URL of real I/O such as
        ``modbus://127.0.0.1:5020`` (``twin.hardware.drivers.open_driver``), paced in real
        time by ``RealTimeLoop``.
    rt_priority : int
        With real I/O: run the loop under SCHED_FIFO at this priority (1 … 99; Linux, needs
        CAP_SYS_NICE; best effort, the summary says whether it was granted). 0: normal.
    """

    machine: str = "tomsk_xy"
    controller_model: str | None = None
    program: str | None = None
    builtin: str = "default"
    profile: str | None = None
    planner: str | None = None
    dcu_order: int | None = None
    period: float | None = None
    overrides: Mapping[str, Any] = field(default_factory=dict)
    mode: str = "extended"
    dry_run: bool = False
    max_time: float = 3600.0
    start: tuple[float, float] | None = None
    commands: tuple[str, ...] = ()
    driver: str = "sim"
    rt_priority: int = 0

    def machine_config(self) -> MachineConfig:
        """The machine with this run's overrides applied (validated)."""
        sets = dict(self.overrides)
        if self.period is not None:
            sets["controller.period"] = self.period
        if self.profile is not None:
            sets["controller.profile"] = self.profile
        if self.planner is not None:
            sets["controller.planner"] = self.planner
        if self.dcu_order is not None:
            sets["controller.regulator.dcu_order"] = self.dcu_order
        return load_machine(self.machine).with_overrides(sets)

    def belief(self, cfg: MachineConfig | None = None) -> MachineConfig:
        """The controller's model of the machine: ``controller_model``, or the machine
        itself (``cfg``, the overridden machine, when given)."""
        if self.controller_model is not None:
            return load_machine(self.controller_model)
        return cfg if cfg is not None else self.machine_config()

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for the run record."""
        d = dataclasses.asdict(self)
        d["overrides"] = dict(self.overrides)
        return d


@dataclass
class RunResult:
    """What a run produced.

    Attributes
    ----------
    summary : dict
        The JSON summary (µm, mm, s; see ``twin run --json``).
    record : dict of ndarray
        The controller's record plus the twin's truth channels, one row per tick.
    path : list of Segment
        The programmed path.
    status : ControllerStatus
        How the controller ended.
    config : MachineConfig or None
        The machine.
    fine : dict of ndarray or None
        The twin's drive-rate samples (``twin.plant.FINE_FIELDS``: one row every drive
        interval) when the run was asked to keep them (``run(keep_fine=True)``).
    """

    summary: dict[str, Any]
    record: dict[str, np.ndarray]
    path: list
    status: ControllerStatus
    config: MachineConfig | None = None
    fine: dict[str, np.ndarray] | None = None


def axis_models(cfg: MachineConfig) -> list[LinearAxisModel]:
    """The linear reference → position model of each axis, from the drive model."""
    return [LinearAxisModel(*axis_transfer_function(cfg.axes[a])) for a in AXES]


def model_options(belief: MachineConfig) -> dict[str, Any]:
    """What a ``Controller`` derives its model-based settings from: the axis models and the
    axes of the machine it believes it runs (``RunSpec.belief``)."""
    return {"axis_models": axis_models(belief), "model_axes": belief.axes}


def load_program(spec: RunSpec, cfg: MachineConfig, start: np.ndarray,
                 notes: list[str] | None = None) -> list[Any]:
    """Parse the G-code file (``GCodeError`` with line and column before any motion) or
    build the built-in program from ``start``. Bytes of the file that are not UTF-8 are
    read as U+FFFD, each place noted in ``notes`` (``gcode.decode_program``)."""
    if spec.program is None:
        if spec.builtin == "none":
            return []
        return build_program(spec.builtin, cfg, start)
    path = Path(spec.program)
    if not path.is_file():
        raise ConfigError("program", f"no such file: {spec.program}")
    text, found = decode_program(path.read_bytes())
    if notes is not None:
        notes.extend(f"{path.name}: {n}" for n in found)
    return list(parse(text, start=tuple(start.tolist())))


@dataclass
class Prepared:
    """A run wired and ready to tick (``plant`` is None behind real I/O)."""

    cfg: MachineConfig
    items: list[Any]
    path: list
    plant: Plant | None
    controller: Controller
    driver: Any
    belief: MachineConfig | None = None
    """The controller's model of the machine (None: ``cfg`` itself)."""
    notes: list[str] = field(default_factory=list)
    """What was read but is worth a look (bytes of the program that are not UTF-8)."""


def prepare(spec: RunSpec) -> Prepared:
    """Load the machine, the program and the machine's I/O (the twin, or a driver URL); build
    the controller (checks the program against the work zone before any motion)."""
    cfg = spec.machine_config()
    belief = spec.belief(cfg)
    plant = None
    if spec.driver == "sim":
        plant = Plant.from_machine(cfg)
        plant.reset(positions=None if spec.start is None else np.asarray(spec.start, float))
        start = plant.truth().table_position
        driver = SimDriver(plant, cfg.controller.period, dry_run=spec.dry_run,
                           timing=cfg.controller.timing)
    else:
        from twin.hardware.drivers import open_driver

        driver = open_driver(spec.driver, cfg)
        start = measured_position(driver.read().encoder_counts, cfg)
    notes: list[str] = []
    try:
        items = load_program(spec, cfg, start, notes)
        controller = Controller.from_machine(cfg, items or None, **model_options(belief),
                                             mode=spec.mode, start=start)
    except BaseException:
        driver.close()
        raise
    return Prepared(cfg, items, program_path(items), plant, controller, driver, belief, notes)


def measured_position(counts: np.ndarray, cfg: MachineConfig) -> np.ndarray:
    """Table position (m) of raw counter values read as signed numbers of their width."""
    out = np.empty(2)
    for k, a in enumerate(AXES):
        bits = cfg.axes[a].encoder.bits
        c = int(counts[k]) & ((1 << bits) - 1)
        out[k] = (c - (1 << bits) if c >= 1 << (bits - 1) else c) / cfg.axes[a].counts_per_metre
    return out


def run(spec: RunSpec, *, out_dir: str | Path = "runs", rerun: str = "file",
        run_id: str | None = None, sink: Sink | None = None,
        progress: Callable[[float, float], None] | None = None,
        prepared: Prepared | None = None,
        commands: Sequence[Callable[[Controller], None]] = (),
        keep_fine: bool = False, warn: Callable[[str], None] | None = None) -> RunResult:
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
    progress : callable(sim_time, max_time), optional
        Called about every simulated second.
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
    """
    run_id = run_id or time.strftime("%Y%m%d-%H%M%S-") + uuid.uuid4().hex[:6]
    out = output_dir(out_dir)   # before the driver is opened: a bad folder costs nothing
    p = prepared or prepare(spec)
    recording = None
    try:
        pending = [*(parse_command(c) for c in spec.commands), *commands]
        if sink is None:
            sink, recording = make_sink(rerun, out, run_id)
    except BaseException:
        p.driver.close()        # whatever fails once the driver is open closes it
        raise
    loop = _Loop(p, sink, spec.max_time, pending, progress, spec.rt_priority, keep_fine,
                 warn)
    aborted = fault = None
    t_wall = time.perf_counter()
    late: list[int] = []
    try:
        with _stop_signals():
            loop.run_lockstep() if p.plant is not None else loop.run_paced()
    except KeyboardInterrupt as exc:
        aborted = f"interrupted ({_signal_name(exc)})"
    except DriverError as exc:
        fault = ("DRIVER", f"driver fault: {exc}")
    except DeadlineFault as exc:
        fault = ("DEADLINE", str(exc))
    except Exception as exc:
        aborted = f"{type(exc).__name__}: {exc}"
        raise
    finally:
        wall = time.perf_counter() - t_wall
        with _deferred_interrupt(late):  # a second signal must not lose the record
            result = loop.finish(spec, run_id, out, recording, wall, aborted, fault)
    if late:
        raise RunInterrupted(result, late[0])
    return result


class _Loop:
    """The cyclic loop of one run and its records (controller, twin truth, telemetry)."""

    def __init__(self, p: Prepared, sink: Sink, max_time: float,
                 pending: list[Callable[[Controller], None]],
                 progress: Callable[[float, float], None] | None, rt_priority: int = 0,
                 keep_fine: bool = False, warn: Callable[[str], None] | None = None):
        self.p, self.sink, self.pending, self.progress = p, sink, pending, progress
        self.rt_priority = rt_priority
        self.rt_granted = False
        self.warn = warn
        self.deadline_warnings: list[str] = []
        self.period = p.cfg.controller.period
        self.max_time = max_time
        self.limit = round(max_time / self.period)
        # Telemetry goes out in batches: every 50 ticks the wall clock is checked and a batch
        # is sent when BATCH_WALL seconds have passed (a few per second for a live viewer,
        # few enough that send overhead stays small).
        self.every = 50
        self._next_batch = time.perf_counter() + BATCH_WALL
        self.truth = Record(TRUTH_FIELDS) if p.plant is not None else None
        self.writer = TelemetryWriter(sink, p.path, truth_record=self.truth,
                                      fine_fields=FINE_FIELDS)
        self.names = {int(s): s.name for s in ControllerStatus}
        self.ticks = 0
        self.stats: TickStats | None = None
        # the twin's drive-rate samples: to the telemetry, into the elastic oscillation
        # (streamed: memory does not grow with the run), and kept only when asked
        self.meter = None if p.plant is None else OscillationMeter(
            [max(1, round(period / p.plant.drive_dt)) | 1 for period in mode_periods(p.cfg)])
        self.kept: list[np.ndarray] | None = [] if keep_fine and p.plant is not None else None
        self._deflection = [_FINE_COLUMNS["screw_deflection"],
                            _FINE_COLUMNS["screw_deflection"] + 1]

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
        if not self.pending or ctrl.status not in _READY:
            return False
        self.pending.pop(0)(ctrl)
        return True

    def _batch(self) -> bool:
        """Send a telemetry batch if BATCH_WALL has passed since the last; True if sent."""
        now = time.perf_counter()
        if now < self._next_batch:
            return False
        self._next_batch = now + BATCH_WALL
        self.writer.flush(self.p.controller.record, status_names=self.names)
        if self.progress is not None:
            self.progress(self.ticks * self.period, self.max_time)
        return True

    def run_lockstep(self) -> None:
        """The twin: as fast as the machine allows (the hot loop: locals only, and the
        cyclic garbage collector paused: the loop makes no reference cycles, only short-lived
        tuples, so a collection would scan the whole heap for nothing)."""
        ctrl, drv, plant, truth = self.p.controller, self.p.driver, self.p.plant, self.truth
        tick, read, write = ctrl.tick, drv.read, drv.write
        append, row = truth.append, plant.truth_row
        every, limit = self.every, self.limit
        paused = gc.isenabled()
        gc.disable()
        try:
            while self.ticks < limit:
                if ctrl.done and not self._next_command():
                    break
                write(tick(read()))
                append(row())
                self.ticks += 1
                if self.ticks % every == 0:
                    self.drain()
                    self._batch()
        finally:
            if paused:
                gc.enable()

    def run_paced(self) -> None:
        """Real I/O: one tick per period of wall time, absolute deadlines. Telemetry goes out
        only in a tick's slack: when the time left before the next deadline exceeds 1.5× the
        last batch's cost (a batch is postponed, never allowed to make a tick late)."""
        ctrl, drv, clock = self.p.controller, self.p.driver, time.perf_counter
        loop = RealTimeLoop(self.period)
        cost = [2e-3]  # the last batch's wall time (s): a first guess

        def warning(message: str) -> None:
            self.deadline_warnings.append(message)
            self.sink.event(self.ticks * self.period, message, level="WARN")
            if self.warn is not None:
                self.warn(message)

        policy = DeadlinePolicy.from_config(self.p.cfg.controller.deadlines, self.period,
                                            on_warning=warning)

        def step(_k: int, t: float) -> bool:
            if ctrl.done and not self._next_command():
                return False
            drv.write(ctrl.tick(drv.read()))
            self.ticks += 1
            if self.ticks % self.every == 0:
                t0 = clock()
                if loop.start + t + self.period - t0 > 1.5 * cost[0] and self._batch():
                    cost[0] = clock() - t0
            return True

        try:
            with fifo_priority(self.rt_priority) as granted:
                self.rt_granted = granted
                self.stats = loop.run(step, max_ticks=self.limit, policy=policy)
        finally:
            self.stats = self.stats or loop.last_stats()

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
        self.writer.flush(ctrl.record, status_names=self.names)
        # the recording is completed, but published under its final name only after the
        # summary is written: a .rrd never stands without its .json
        finish = getattr(self.sink, "finish", None)
        if finish is not None:
            finish()
        rec = ctrl.record.as_arrays()
        if self.truth is not None:
            rec.update(self.truth.as_arrays())
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
        summary.update(run_summary(rec, p.path))
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
        if self.deadline_warnings:
            summary["warnings"] = list(self.deadline_warnings)
        if p.notes:
            summary["input_warnings"] = list(p.notes)
        write_json_atomic(out / f"{run_id}.json", summary)
        self.sink.close()
        fine = None
        if self.kept is not None:
            rows = np.concatenate(self.kept) if self.kept else np.zeros((0, FINE_WIDTH))
            fine = {name: rows[:, c:c + w] if w > 1 else rows[:, c]
                    for name, (c, w) in _FINE_SLICES.items()}
        return RunResult(summary, rec, p.path, ctrl.status, p.cfg, fine)


_READY = (ControllerStatus.IDLE, ControllerStatus.FINISHED)


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


STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, n))
"""The signals that stop a run the one way: Ctrl-C, ``kill``/systemd/``docker stop``
(SIGTERM), a closed terminal (SIGHUP)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread where Ctrl-C raises KeyboardInterrupt:
    the run takes the same path (safe stop, record written)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class RunInterrupted(KeyboardInterrupt):
    """A stop signal arrived while the run record was being written. The record is
    complete (``result``); the caller reports it, then honours the signal (``signum``)."""

    def __init__(self, result: RunResult, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.result, self.signum = result, signum


def _signal_name(exc: BaseException) -> str:
    return "Ctrl-C" if not isinstance(exc, Terminated) else signal.Signals(exc.signum).name


def final_status(status: ControllerStatus, aborted: str | None, max_time: float,
                 io_fault: tuple[str, str] | None = None) -> dict[str, Any]:
    """How a run ended, for its record: ``status`` is FINISHED, ABORTED (``aborted`` says
    why: a signal, an error), FAULT (``fault`` names the controller's latched fault, or
    ``io_fault``'s kind: ``DRIVER`` for the machine's I/O, ``DEADLINE`` for the deadline
    policy; its message goes into ``error``) or TIMEOUT (``timeout`` says which limit);
    never a state in progress. ``controller_status`` keeps the controller's own last
    state."""
    out: dict[str, Any] = {"status": "FINISHED", "aborted": aborted,
                           "controller_status": status.name}
    if aborted is not None:
        out["status"] = "ABORTED"
    elif io_fault is not None:
        out["status"] = "FAULT"
        out["fault"] = io_fault[0]
    elif status >= ControllerStatus.LIMIT_TRIP:
        out["status"] = "FAULT"
        out["fault"] = status.name
    elif status not in _READY:
        out["status"] = "TIMEOUT"
        out["timeout"] = (f"max_time ({max_time:g} s) reached while the controller was "
                          f"{status.name}")
    return out


@contextlib.contextmanager
def _stop_signals() -> Iterator[None]:
    """SIGTERM and SIGHUP raise ``Terminated`` in the main thread while the loop runs (SIGINT
    raises KeyboardInterrupt already); the previous handlers come back afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, _frame: Any) -> None:
        raise Terminated(signum)

    previous = {s: signal.signal(s, stop) for s in STOP_SIGNALS if s != signal.SIGINT}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


@contextlib.contextmanager
def _deferred_interrupt(caught: list[int]) -> Iterator[None]:
    """Hold the stop signals while the run record is written; those that arrived are
    appended to ``caught`` (the caller raises ``RunInterrupted`` once the record is
    complete)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, lambda sig, frame: caught.append(sig))
                for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
