"""Setting up a run: what determines it (``RunSpec``), what it returns (``RunResult``), and
the wiring of machine, program, controller and I/O (``prepare``) that
``twin.session.run.run`` ticks.
``twin.session.run`` re-exports these names: it is the one place users import a run from.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig, load_machine
from twin.config.schema import WORK_SYSTEMS
from twin.config.shaper_settings import profile_overrides
from twin.controller.controller import Controller, ControllerStatus
from twin.controller.gcode import Limits, ReaderOptions, decode_program, parse
from twin.controller.library import build_program, program_path
from twin.controller.linear import LinearAxisModel
from twin.drive.linear import axis_transfer_function
from twin.errors import ConfigError
from twin.hardware.sim import SimDriver
from twin.plant import Plant

__all__ = ["Prepared", "RunResult", "RunSpec", "axis_models", "load_program",
           "measured_position", "model_options", "prepare", "reader_options",
           "shipped_program", "wire"]


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
        Acceleration law, or ``law+shaper`` (``trapezoid+mzv``: that input shaper on both
        axes, ``twin.config.shaper_settings``), and planner mode; None: the machine's
        settings.
    dcu_order : int or None
        0 … 3; None: the machine's setting.
    period : float or None
        Controller period (s); None: the machine's.
    overrides : mapping
        ``--set`` values by dotted config path (see ``twin.config.overrides``).
    mode : str
        Interpolator interface: "extended" (float v/a/j channels) or "traditional".
    drives_off : bool
        Run the controller with the drives disabled (seed 001's "dry run": the loop runs,
        the motors get nothing). The plan-only dry run is ``twin.session.dry_run``.
    max_time : float or None
        Stop after this much controller time (s); None: the machine's longest program
        (``controller.max_program_time``, judged on a lower bound of a program's time) with
        a quarter more, plus ``controller.settle_timeout``.
    start : (float, float) or None
        Table position at the start (m); None: the home keyframe.
    commands : tuple of str
        Manual mode instead of a program (``builtin="none"``): ``"home x"``, ``"jog x 10
        mm"`` (relative), ``"goto 50 20 mm"`` (absolute; without ``mm``: metres), run one
        after the other.
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
    drives_off: bool = False
    max_time: float | None = None
    start: tuple[float, float] | None = None
    commands: tuple[str, ...] = ()
    driver: str = "sim"
    rt_priority: int = 0

    def machine_config(self) -> MachineConfig:
        """The machine with this run's overrides applied (validated)."""
        sets = dict(self.overrides)
        if self.period is not None:
            sets["controller.period"] = self.period
        if self.profile is not None:          # "law" or "law+shaper"
            sets.update(profile_overrides(self.profile))
        if self.planner is not None:
            sets["controller.planner"] = self.planner
        if self.dcu_order is not None:
            sets["controller.regulator.dcu_order"] = self.dcu_order
        return load_machine(self.machine).with_overrides(sets)

    def time_limit(self, cfg: MachineConfig) -> float:
        """``max_time``, or the machine's default for it (s)."""
        if self.max_time is not None:
            return self.max_time
        c = cfg.controller
        return 1.25 * c.max_program_time + c.settle_timeout

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
    """The linear reference → position model of each axis, from the drive model; the X
    axis moves the Y carriage too (``MachineConfig.moving_masses``), as the plant's drives do.

    Raises
    ------
    ConfigError
        Naming the axis, when its motor, converter, tacho and speed-loop settings give a
        model the controller cannot derive its gains from (an unstable speed loop)."""
    models = []
    masses = cfg.moving_masses()
    for a in AXES:
        try:
            models.append(LinearAxisModel(*axis_transfer_function(cfg.axes[a],
                                                                  moving_mass=masses[a])))
        except ConfigError as exc:
            raise ConfigError(f"axes.{a}", f"the drive these motor, converter, tacho and "
                              f"speed_loop settings give is not a stable linear model "
                              f"({exc.field}: {exc.message})") from None
    return models


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
    path = shipped_program(spec.program)
    text, found = decode_program(path.read_bytes())
    if notes is not None:
        notes.extend(f"{path.name}: {n}" for n in found)
    return list(parse(text, start=tuple(start.tolist()), options=reader_options(cfg),
                      folder=str(path.resolve().parent)))


SHIPPED_PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
"""The example programs that come with xy-twin (``twin/programs``)."""


def shipped_program(name: str) -> Path:
    """The program file ``name``: a path as given, or else, for a relative path whose file
    is one of the shipped examples, that example (``twin run twin/programs/x.ngc`` and
    ``twin run x.ngc`` work from any folder).

    Raises
    ------
    ConfigError
        ``program``: no such file, naming the shipped examples.
    """
    path = Path(name)
    if path.is_file():
        return path
    shipped = SHIPPED_PROGRAMS / path.name
    if not path.is_absolute() and shipped.is_file():
        return shipped
    examples = ", ".join(sorted(p.name for p in SHIPPED_PROGRAMS.glob("*.ngc")))
    raise ConfigError("program", f"no such file: {name} (the shipped examples, found from "
                      f"any folder by name: {examples})")


def reader_options(cfg: MachineConfig) -> ReaderOptions:
    """The G-code reader's options from the machine's ``controller.gcode`` section; its
    relative subroutine folders are taken from the machine file's folder (the working
    folder for a machine built in memory)."""
    g = cfg.controller.gcode
    home = Path(cfg.source).parent if cfg.source and Path(cfg.source).is_file() else Path()
    return ReaderOptions(z=g.z, tool_z=g.tool_z,
                         limits=Limits(loop_iterations=int(g.loop_iterations),
                                       call_depth=int(g.call_depth),
                                       subroutine_path=tuple(
                                           str(home / folder) for folder in
                                           g.subroutine_path)),
                         work_offsets={WORK_SYSTEMS.index(name) + 1: offset
                                       for name, offset in g.work_offsets.items()})


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


RECORD_CHUNK = 4096
"""Rows per chunk of a run's records (20 s at 200 Hz): a run that does not keep its record
releases it chunk by chunk once the telemetry and the summary have consumed it."""


def prepare(spec: RunSpec) -> Prepared:
    """Load the machine, the program and the machine's I/O (the twin, or a driver URL); build
    the controller (checks the program against the work zone before any motion)."""
    cfg = spec.machine_config()
    notes: list[str] = []
    p = wire(cfg, lambda start: load_program(spec, cfg, start, notes),
             belief=spec.belief(cfg), start=spec.start, driver=spec.driver,
             drives_off=spec.drives_off, mode=spec.mode, record_capacity=RECORD_CHUNK)
    p.notes = notes
    return p


def wire(cfg: MachineConfig, program: Callable[[np.ndarray], list[Any]] | None = None, *,
         belief: MachineConfig | None = None, start: Sequence[float] | None = None,
         driver: str = "sim", drives_off: bool = False, **controller_options: Any
         ) -> Prepared:
    """The one wiring of a machine, a program and the controller, for runs, tuning,
    environments and experiments.

    Parameters
    ----------
    cfg : MachineConfig
        The machine: the plant's truth on the twin, and the controller's settings and I/O.
    program : callable(start) -> list, optional
        Builds the program's items from the table's start position (m); None: the
        controller starts idle (for jogs, homing and test signals).
    belief : MachineConfig, optional
        The controller's model of the machine (``model_options``); default ``cfg``.
    start : (float, float), optional
        Table position on the twin (m); default the home keyframe. Behind real I/O the
        table is where the counters say.
    driver : str
        ``"sim"``: the twin in lock-step (``SimDriver`` with the machine's timing); or a
        URL of real I/O (``twin.hardware.drivers.open_driver``).
    drives_off : bool
        The twin's drives disabled whatever the controller writes (a dry run).
    **controller_options
        More ``Controller`` options (``gains``, ``axis_models``, ``dcu_order``, ``mode``,
        …); they take precedence over those derived from ``belief``.
    """
    plant = None
    if driver == "sim":
        plant = Plant.from_machine(cfg)
        plant.reset(positions=None if start is None else np.asarray(start, float))
        here = plant.truth().table_position
        io: Any = SimDriver(plant, cfg.controller.period, drives_off=drives_off,
                            timing=cfg.controller.timing)
    else:
        from twin.hardware.drivers import open_driver

        io = open_driver(driver, cfg)
        here = measured_position(io.read().encoder_counts, cfg)
    try:
        items = program(here) if program is not None else []
        options = dict(controller_options)
        model = belief or cfg
        options.setdefault("model_axes", model.axes)
        if "axis_models" not in options:   # derived only when needed: not free
            options["axis_models"] = axis_models(model)
        controller = Controller.from_machine(cfg, items or None, start=here, **options)
    except BaseException:
        io.close()
        raise
    return Prepared(cfg, items, program_path(items), plant, controller, io, belief)


def measured_position(counts: np.ndarray, cfg: MachineConfig) -> np.ndarray:
    """Table position (m) of raw counter values read as signed numbers of their width."""
    out = np.empty(2)
    for k, a in enumerate(AXES):
        bits = cfg.axes[a].encoder.bits
        c = int(counts[k]) & ((1 << bits) - 1)
        out[k] = (c - (1 << bits) if c >= 1 << (bits - 1) else c) / cfg.axes[a].counts_per_metre
    return out
