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
import json
import math
import os
import signal
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig, load_machine
from twin.controller.controller import Controller, ControllerStatus
from twin.controller.gcode import parse
from twin.controller.library import build_program, program_path
from twin.controller.linear import LinearAxisModel
from twin.controller.record import Record
from twin.controller.summary import summarize
from twin.drive.linear import axis_transfer_function
from twin.errors import ConfigError
from twin.hardware.realtime import TickStats
from twin.hardware.sim import SimDriver
from twin.overrides import parse_sets
from twin.plant import Plant
from twin.telemetry.channels import TRUTH_FIELDS, TelemetryWriter
from twin.telemetry.sink import NullSink, Sink

__all__ = ["RunResult", "RunSpec", "axis_models", "load_program", "parse_command", "prepare",
           "run",
           "write_json_atomic"]


@dataclass(frozen=True)
class RunSpec:
    """Everything that determines a run (saved in the run's JSON, so it can be repeated).

    Attributes
    ----------
    machine : str
        Preset name or TOML path.
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
    """

    machine: str = "tomsk_xy"
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
    """

    summary: dict[str, Any]
    record: dict[str, np.ndarray]
    path: list
    status: ControllerStatus
    config: MachineConfig | None = None


def axis_models(cfg: MachineConfig) -> list[LinearAxisModel]:
    """The linear reference → position model of each axis, from the drive model."""
    return [LinearAxisModel(*axis_transfer_function(cfg.axes[a])) for a in AXES]


def load_program(spec: RunSpec, cfg: MachineConfig, start: np.ndarray) -> list[Any]:
    """Parse the G-code file (``GCodeError`` with line and column before any motion) or
    build the built-in program from ``start``."""
    if spec.program is None:
        if spec.builtin == "none":
            return []
        return build_program(spec.builtin, cfg, start)
    path = Path(spec.program)
    if not path.is_file():
        raise ConfigError("program", f"no such file: {spec.program}")
    return list(parse(path.read_text(encoding="utf-8"), start=tuple(start.tolist())))


@dataclass
class Prepared:
    """A run wired and ready to tick."""

    cfg: MachineConfig
    items: list[Any]
    path: list
    plant: Plant
    controller: Controller
    driver: Any


def prepare(spec: RunSpec) -> Prepared:
    """Load the machine, the program and the twin; build the controller (checks the
    program against the work zone before any motion)."""
    cfg = spec.machine_config()
    plant = Plant.from_machine(cfg)
    plant.reset(positions=None if spec.start is None else np.asarray(spec.start, float))
    start = plant.truth().table_position
    items = load_program(spec, cfg, start)
    controller = Controller.from_machine(cfg, items or None, axis_models=axis_models(cfg),
                                         mode=spec.mode, start=start)
    driver = SimDriver(plant, cfg.controller.period, dry_run=spec.dry_run)
    return Prepared(cfg, items, program_path(items), plant, controller, driver)


def write_json_atomic(path: Path, obj: Any) -> None:
    """Write JSON to ``path`` via a temporary file and ``os.replace``."""
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps(obj, indent=2, default=_json_default) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if dataclasses.is_dataclass(obj):
        return dataclasses.asdict(obj)
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def run(spec: RunSpec, *, out_dir: str | Path = "runs", rerun: str = "file",
        run_id: str | None = None, sink: Sink | None = None,
        progress: Callable[[float, float], None] | None = None,
        prepared: Prepared | None = None,
        commands: Sequence[Callable[[Controller], None]] = ()) -> RunResult:
    """Run ``spec`` on the twin in lock-step and write ``<run_id>.rrd`` and ``.json``.

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
    """
    run_id = run_id or time.strftime("%Y%m%d-%H%M%S-") + uuid.uuid4().hex[:6]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    p = prepared or prepare(spec)
    recording = None
    if sink is None:
        sink, recording = _make_sink(rerun, out, run_id)
    truth = Record(TRUTH_FIELDS)
    writer = TelemetryWriter(sink, p.path, truth_record=truth)
    names = {int(s): s.name for s in ControllerStatus}
    ctrl, drv, plant = p.controller, p.driver, p.plant
    limit = round(spec.max_time / p.cfg.controller.period)
    every = max(1, round(1.0 / p.cfg.controller.period))
    aborted = None
    ticks = 0
    t_wall = time.perf_counter()
    pending = [*(parse_command(c) for c in spec.commands), *commands]
    try:
        while ticks < limit:
            if ctrl.done:
                if not pending or ctrl.status not in _READY:
                    break
                pending.pop(0)(ctrl)
            drv.write(ctrl.tick(drv.read()))
            truth.append(_truth_row(plant))
            ticks += 1
            if ticks % every == 0:
                writer.flush(ctrl.record, status_names=names)
                if progress is not None:
                    progress(ticks * p.cfg.controller.period, spec.max_time)
    except KeyboardInterrupt:
        aborted = "interrupted (Ctrl-C)"
    except Exception as exc:  # a driver or simulation fault: stop safely, keep the record
        aborted = f"{type(exc).__name__}: {exc}"
        raise
    finally:
        wall = time.perf_counter() - t_wall
        with _deferred_interrupt():  # a second Ctrl-C must not lose the record
            while len(truth) < len(ctrl.record):  # interrupted between the two appends
                truth.append(_truth_row(plant))
            drv.close()
            writer.flush(ctrl.record, status_names=names)
            sink.close()
            result = _finish(spec, p, run_id, out, recording, ticks, wall, aborted, writer,
                             truth)
    return result


@contextlib.contextmanager
def _deferred_interrupt() -> Iterator[None]:
    """Hold SIGINT while the run record is written; re-raise it afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda sig, frame: caught.append(sig))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt


def _truth_row(plant: Plant) -> tuple[float, ...]:
    tr = plant.truth()
    return (*tr.table_position.tolist(), *tr.table_velocity.tolist(),
            *tr.screw_deflection.tolist(), *tr.armature_current.tolist(),
            *tr.converter_voltage.tolist())


_READY = (ControllerStatus.IDLE, ControllerStatus.FINISHED)


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


def _make_sink(rerun: str, out: Path, run_id: str) -> tuple[Sink, str | None]:
    if rerun == "none":
        return NullSink(), None
    from twin.telemetry.rerun_sink import RerunSink

    if rerun.endswith(".rrd"):
        path = Path(rerun)
        live = None
    elif rerun in ("file", "spawn", "serve"):
        path = out / f"{run_id}.rrd"
        live = None if rerun == "file" else rerun
    else:
        raise ConfigError("rerun", f"must be spawn, serve, none, file or a path ending in "
                          f".rrd, got {rerun!r}")
    return RerunSink(path, live=live, recording_id=run_id, recording_name=run_id), str(path)


def _finish(spec: RunSpec, p: Prepared, run_id: str, out: Path, recording: str | None,
            ticks: int, wall: float, aborted: str | None, writer: TelemetryWriter,
            truth: Record) -> RunResult:
    rec = p.controller.record.as_arrays()
    rec.update(truth.as_arrays())
    period = p.cfg.controller.period
    sim_time = ticks * period
    summary: dict[str, Any] = {"run_id": run_id, "status": p.controller.status.name,
                               "aborted": aborted, "machine": p.cfg.name}
    summary.update(run_summary(rec, p.path))
    summary.update({
        "sim_time_s": sim_time,
        "wall_time_s": wall,
        "real_time_factor": sim_time / wall if wall > 0 else math.inf,
        "telemetry_wall_s": writer.wall,
        "recording": recording,
        "ticks": _ticks_dict(TickStats.lockstep(period, ticks)),
        "spec": spec.to_dict(),
        "config": dataclasses.asdict(p.cfg),
    })
    if p.controller.error is not None:
        summary["error"] = str(p.controller.error)
    write_json_atomic(out / f"{run_id}.json", summary)
    return RunResult(summary, rec, p.path, p.controller.status, p.cfg)


def _ticks_dict(stats: TickStats) -> dict[str, Any]:
    d = stats.to_dict()
    return {"due": d["due"], "on_time": d["on_time"], "late": d["late"],
            "skipped": d["skipped"], "jitter_p50_us": d["jitter_p50_us"],
            "jitter_p99_us": d["jitter_p99_us"], "jitter_max_us": d["jitter_max_us"],
            "paced": d["paced"]}


def run_summary(rec: Mapping[str, np.ndarray], path: list) -> dict[str, Any]:
    """The metric part of the summary (µm, mm, s) from a run's record."""
    if len(rec["t"]) == 0 or not path:
        return {"cycle_time_s": 0.0, "path_length_mm": 0.0}
    segment = np.clip(rec["block"], 0, len(path) - 1)
    m = summarize(rec["t"], rec["ref_position"], rec["ref_velocity"], rec["position"],
                  rec["table_velocity"], path, segment=segment)
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
        "residual_vibration_um": r["residual_vibration_um"],
        "overshoot_um": r["overshoot_um"],
        "productivity_mm_per_min": r["productivity_mm_per_min"],
    }


__all__ += ["parse_sets", "run_summary"]
