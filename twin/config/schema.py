"""The machine schema: frozen, validated dataclasses for every section of a machine file.

Every numeric field carries its unit and physical range in its metadata
(``twin.config.fields``); ``__post_init__`` checks them and raises ``ConfigError`` naming the
field. The axis sections are in ``twin.config.axis``; this module holds the controller's
settings, the simulation's and the whole machine with its checks across sections, and
re-exports the axis sections. Loading (TOML, dotted overrides) is in ``twin.config.loader``.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from twin.config.axis import (
    STIFFNESS_RANGE,
    AxisConfig,
    ConverterConfig,
    DacConfig,
    EncoderConfig,
    LimitsConfig,
    MechanicsConfig,
    MotorConfig,
    RegulatorsConfig,
    SpeedLoopConfig,
    SwitchConfig,
    TachoConfig,
    TransmissionConfig,
)
from twin.config.build import from_dict, set_path, to_raw
from twin.config.compensation_settings import CompensationSettings
from twin.config.fields import Validated, choice, flag, num, range_text, spec
from twin.config.shaper_settings import ShaperAxes
from twin.errors import ConfigError

__all__ = [
    "AXES",
    "AccelerometerConfig",
    "AxisConfig",
    "ControllerSettings",
    "ConverterConfig",
    "DacConfig",
    "DeadlineConfig",
    "EncoderConfig",
    "GcodeSettings",
    "HilSettings",
    "LimitsConfig",
    "MachineConfig",
    "MechanicsConfig",
    "MotorConfig",
    "RegulatorSettings",
    "RegulatorsConfig",
    "SimulationConfig",
    "SpeedLoopConfig",
    "SwitchConfig",
    "TachoConfig",
    "TimingConfig",
    "TransmissionConfig",
    "field_meta",
    "field_unit",
    "machine_from_raw",
    "moving_masses",
    "range_text",
]

AXES = ("x", "y")


ELASTIC_STEP = 0.5
"""Largest ω·timestep of an axis' elastic mode (see ``MachineConfig._check_elastic_modes``)."""

PROFILES = ("trapezoid", "parabolic", "cosine", "cubic", "jerk-limited")
"""The acceleration laws (``twin.controller.profiles.laws.LAWS``; a test keeps them equal)."""

PLANNERS = ("lookahead", "stop")
"""The planner's modes (``twin.controller.planner.MODES``)."""


# --------------------------------------------------------------------------- controller
@dataclass(frozen=True, kw_only=True)
class RegulatorSettings(Validated):
    """Position regulator of both axes. ``None`` means: derive from the drive model.

    Each gain is one number for both axes or an ``[x, y]`` pair. ``dcu_alpha`` (``[[α1, α2,
    α3], [α1, α2, α3]]``, V/m, x then y) replaces the DCU that ``dcu_order`` would derive —
    what a tuning job writes (``twin tune`` → ``twin run --set-file``).
    """

    kp: float | tuple[float, float] | None = num(None, "V/m", ge=0, le=1e7,
                                                 doc="proportional gain")
    ki: float | tuple[float, float] | None = num(None, "V/(m·s)", ge=0, le=1e9,
                                                 doc="integral gain")
    kd: float | tuple[float, float] | None = num(None, "V·s/m", ge=0, le=1e5,
                                                 doc="derivative gain")
    ff1: float | tuple[float, float] | None = num(None, "V·s/m", ge=0, le=1e5,
                                                  doc="velocity feed-forward")
    ff2: float | tuple[float, float] | None = num(None, "V·s²/m", ge=0, le=1e4,
                                                  doc="acceleration feed-forward")
    ff3: float | tuple[float, float] | None = num(None, "V·s³/m", ge=0, le=1e3,
                                                  doc="jerk feed-forward")
    dcu_order: int = num(0, "1", ge=0, le=3, doc="order of the derived DCU; 0 = off")
    dcu_alpha: tuple[tuple[float, float, float], tuple[float, float, float]] | None = num(
        None, "V/m", ge=-1e9, le=1e9, doc="the DCU's coefficients, x then y")
    following_error_limit: float = num(2e-3, "m", display="µm", ge=1e-7, le=1.0,
                                       doc="a larger following error trips the axis")


@dataclass(frozen=True, kw_only=True)
class TimingConfig(Validated):
    """When the controller's ticks really come, on the twin (simulation only).

    Off by default: every tick exactly one period after the last, as on a real-time
    system. Otherwise each tick is due one period after the last *due* instant
    (``rearm = "absolute"``: a periodic timer) or after the last tick *taken*
    (``"relative"``: a timer re-armed by its handler), fires only at a multiple of
    ``granularity`` (the OS clock tick), and is then late by up to ``late_max`` with
    probability ``late_probability`` or skipped with ``skip_probability``; the controller
    still assumes one period between ticks. Seeded, so a run is reproducible.

    Seed 000's plain software timer is ``granularity = 0.015625`` (the 64 Hz clock of the
    PC's OS) with ``rearm = "relative"``: 9/16/64/64 ticks per second at 100/50/10/5 ms
    against the 9/15/62/63 measured (``twin.hardware.timing``,
    ``tests/hardware/test_timing.py``).
    """

    granularity: float = num(0.0, "s", ge=0, le=1.0, doc="OS clock tick; 0 = exact")
    rearm: str = choice("absolute", ("absolute", "relative"),
                        "a periodic timer, or one re-armed by its handler")
    late_probability: float = num(0.0, "1", ge=0, le=1, doc="chance that a tick is late")
    late_max: float = num(0.0, "s", ge=0, le=1.0, doc="a late tick comes up to this late")
    skip_probability: float = num(0.0, "1", ge=0, le=1, doc="chance that a tick is lost")
    seed: int = num(0, "1", ge=0, le=2**32 - 1, doc="seed of the timer's randomness")

    def _check(self) -> None:
        if self.rearm not in ("absolute", "relative"):
            raise ConfigError("rearm", f"must be 'absolute' or 'relative', got {self.rearm!r}")
        if self.late_probability + self.skip_probability > 1.0:
            raise ConfigError("skip_probability", "late_probability + skip_probability must "
                              "not exceed 1")
        if self.late_probability > 0.0 and self.late_max <= 0.0:
            raise ConfigError("late_max", "must be > 0 (s) when late_probability > 0")

    @property
    def ideal(self) -> bool:
        """Every tick exactly on time."""
        return (self.granularity == 0.0 and self.late_probability == 0.0
                and self.skip_probability == 0.0)


@dataclass(frozen=True, kw_only=True)
class DeadlineConfig(Validated):
    """What a paced run (real I/O) does about missed deadlines.

    A position loop that misses its periods is not controlling the machine: the run stops
    with a FAULT naming this policy when more than ``max_skipped_in_a_row`` consecutive
    periods are lost, or when, over the last ``window`` seconds, fewer than
    ``min_on_time`` of the periods started on time. A live warning comes first, once the
    on-time share falls below ``warn_on_time``.
    """

    max_skipped_in_a_row: int = num(4, "periods", ge=0, le=1000,
                                    doc="more lost periods in a row stop the run")
    window: float = num(1.0, "s", gt=0, le=600.0, doc="span of the on-time share")
    min_on_time: float = num(0.9, "1", ge=0, le=1, doc="a lower on-time share stops the run")
    warn_on_time: float = num(0.97, "1", ge=0, le=1,
                              doc="a lower on-time share is warned about")

    def _check(self) -> None:
        if self.warn_on_time < self.min_on_time:
            raise ConfigError("warn_on_time", f"must be >= min_on_time ({self.min_on_time}), "
                              f"got {self.warn_on_time}")


WORK_SYSTEMS = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
"""The work coordinate systems, 1 to 9, as ``controller.gcode.work_offsets`` names them."""


@dataclass(frozen=True, kw_only=True)
class GcodeSettings(Validated):
    """How programs are read (``twin.controller.gcode.ReaderOptions``)."""

    z: str = choice("error", ("error", "ignore", "tool"), "Z words on this two-axis "
                    "machine: refuse them, ignore them, or run Z and M3/M5 as the tool on "
                    "and off (pen plotters, lasers)")
    tool_z: float = num(0.0, "m", ge=-1.0, le=1.0, doc="with z = \"tool\": work Z at or "
                        "below which the tool is on")
    loop_iterations: int = num(100_000, "1", ge=1, le=100_000_000,
                               doc="most passes of one O-word loop (a runaway loop is an "
                               "error at its line)")
    call_depth: int = num(64, "1", ge=1, le=10_000, doc="most subroutine calls open at once")
    subroutine_path: tuple[str, ...] = field(
        default=(), metadata={"doc": "folders searched for name.ngc when O<name> call names a "
                              "subroutine the program does not define, after the program's "
                              "own folder (LinuxCNC's SUBROUTINE_PATH); a relative folder "
                              "is taken from the machine file's folder. Nothing outside "
                              "these folders is read"})
    work_offsets: dict[str, tuple[float, float]] = field(
        default_factory=dict, metadata={"doc": "work offsets of the machine, e.g. G55 = "
                                        "[0.1, 0.05]: where each coordinate system's zero is "
                                        "(m, machine coordinates, each within ±1 m); G10 L2 "
                                        "in a program changes them for that run"})

    def _check(self) -> None:
        for i, folder in enumerate(self.subroutine_path):
            if not folder or "\0" in folder:
                raise ConfigError(f"subroutine_path[{i}]", f"must name a folder, got "
                                  f"{folder!r}")
        for name, offset in self.work_offsets.items():
            if name not in WORK_SYSTEMS:
                raise ConfigError(f"work_offsets.{name}", f"must be one of "
                                  f"{', '.join(WORK_SYSTEMS)}")
            if not all(abs(v) <= 1.0 for v in offset):
                raise ConfigError(f"work_offsets.{name}", f"must lie within ±1 m, got "
                                  f"{list(offset)}")


@dataclass(frozen=True, kw_only=True)
class ControllerSettings(Validated):
    """The CNC: period, contour limits, planner and regulator settings."""

    period: float = num(5e-3, "s", display="ms", ge=1e-4, le=0.1, doc="the position loop's period")
    limits: LimitsConfig = field(
        default_factory=lambda: LimitsConfig(max_velocity=0.015, max_acceleration=0.2,
                                             max_jerk=5.0))
    rapid_velocity: float = num(0.015, "m/s", ge=1e-4, le=100.0, doc="speed of G0 moves")
    contour_tolerance: float = num(20e-6, "m", display="µm", ge=1e-9, le=1.0,
                                   doc="largest deviation from the path at a corner (a "
                                   "study of corners without this limit sets 1 m)")
    profile: str = choice("parabolic", PROFILES, "the acceleration law")
    planner: str = choice("lookahead", PLANNERS, "look ahead over the blocks, or stop at "
                          "every node")
    lookahead: int = num(4096, "blocks", ge=1, le=100_000,
                         doc="most blocks the planner looks ahead (it looks as far as "
                         "the braking distance needs, up to this)")
    corner_blend: float = num(0.5, "1", ge=0.0, le=1.0,
                              doc="share of the contour tolerance that rounding the corners "
                              "between lines may take (0: sharp corners); the rest is the "
                              "servo's")
    soft_limits: bool = flag(True, "refuse motion outside the work zone")
    """Refuse motion outside the work zone (the travel between the end switches)."""
    in_position_tolerance: float = num(
        1e-6, "m", display="µm", ge=1e-9, le=1e-3,
        doc="after the motion the loop stays closed until every "
        "axis' following error is within this (seed 000: 1 µm positioning accuracy)")
    settle_timeout: float = num(2.0, "s", ge=1e-3, le=60.0,
                                doc="longest wait for the in-position tolerance")
    min_feed: float = num(1e-6, "m/s", ge=1e-9, le=1.0, doc="slowest programmed feed "
                          "accepted (0.06 mm/min): a slower F is refused at its line")
    max_program_time: float = num(
        86400.0, "s", ge=1.0, le=3.2e7, doc="longest a program may take, judged by a lower "
        "bound (every move at its full feed, plus the dwells): beyond it the program is "
        "refused at the line that passes it")
    regulator: RegulatorSettings = field(default_factory=RegulatorSettings)
    gcode: GcodeSettings = field(default_factory=GcodeSettings)
    timing: TimingConfig = field(default_factory=TimingConfig)
    deadlines: DeadlineConfig = field(default_factory=DeadlineConfig)
    shaper: ShaperAxes = field(default_factory=ShaperAxes)
    compensation: CompensationSettings = field(default_factory=CompensationSettings)

    def _check(self) -> None:
        self.shaper.check_nyquist(self.period)


@dataclass(frozen=True, kw_only=True)
class SimulationConfig(Validated):
    """Physics integration of the twin (chosen by the convergence test)."""

    timestep: float = num(2e-4, "s", ge=1e-6, le=1e-2, doc="MuJoCo's time step")
    drive_substeps: int = num(5, "1", ge=1, le=1000, doc="physics steps per drive update")
    seed: int = num(0, "1", ge=0, le=2**32 - 1, doc="seed of the sensor noise")


@dataclass(frozen=True, kw_only=True)
class HilSettings(Validated):
    """The twin standing in for the I/O module (``twin hil-server``)."""

    owners: tuple[str, ...] = field(
        default=(), metadata={"doc": "the clients that may claim the outputs (drive the "
                              "table): host names, addresses or networks (10.0.0.0/24); "
                              "others may only read. Empty: the first client to feed the "
                              "watchdog, as an I/O module without an access list"})

    def _check(self) -> None:
        for i, owner in enumerate(self.owners):
            if not owner.strip() or any(c.isspace() or c == "\0" for c in owner):
                raise ConfigError(f"owners[{i}]", f"must be a host, an address or a "
                                  f"network, got {owner!r}")


@dataclass(frozen=True, kw_only=True)
class AccelerometerConfig(Validated):
    """A two-channel accelerometer clamped on the table (the Y carriage, which the X
    carriage carries): channel x sees the X slide's acceleration, channel y the Y slide's.
    Modelled on an ADXL345 as engineers clamp one on for a resonance test: it samples at
    its own rate into a FIFO of ``block`` samples, which the I/O reads once per controller
    period (one request; samples beyond a full FIFO are lost and flagged). Each sample is
    the mean acceleration over its sample interval (the sensor's own averaging), plus white
    noise of ``noise_density``, rounded to ``resolution`` and clipped to ``±range``
    (``twin.plant.accelerometer``)."""

    mounted: bool = flag(False, "an accelerometer is on the table (twin measure mounts one "
                         "on the twin for its measurement when the file has none)")
    range: float = num(156.9, "m/s²", gt=0.0, le=1e4, doc="full scale, ±range (ADXL345: "
                       "±16 g)")
    resolution: float = num(0.0383, "m/s²", gt=0.0, le=100.0, doc="one count of the "
                            "sensor's output (ADXL345 full resolution: 3.9 mg)")
    noise_density: float = num(4.0e-3, "m/s²/√Hz", ge=0.0, le=10.0, doc="white noise "
                               "spectral density of each channel (ADXL345: ≈ 400 µg/√Hz)")
    sample_rate: float = num(3200.0, "Hz", ge=10.0, le=1e5, doc="output data rate")
    block: int = num(32, "1", ge=1, le=56, doc="FIFO depth: the most samples one read "
                     "returns (ADXL345: 32); at most 56, what one Modbus read carries")
    seed: int = num(0, "1", ge=0, le=2**32 - 1, doc="seed of the sensor's noise (its own "
                    "stream: mounting it changes no other noise)")

    def _check(self) -> None:
        if self.resolution > self.range:
            raise ConfigError("resolution", f"must not exceed the range {self.range:g} m/s², "
                              f"got {self.resolution:g}")

    @property
    def noise_rms(self) -> float:
        """Standard deviation of one sample's noise (m/s²): the density over the sensor's
        Nyquist band, noise_density·√(sample_rate/2)."""
        return self.noise_density * (0.5 * self.sample_rate) ** 0.5


def moving_masses(axes: Mapping[str, AxisConfig]) -> dict[str, float]:
    """Mass moved by each axis of the cross table (kg), the one place it is computed: the
    lower axis (x) carries the upper carriage (y)."""
    mx = axes["x"].mechanics.carriage_mass
    my = axes["y"].mechanics.carriage_mass
    return {"x": mx + my, "y": my}


@dataclass(frozen=True, kw_only=True)
class MachineConfig(Validated):
    """A whole machine: two axes, the controller's settings, the simulation settings."""

    name: str
    description: str
    axes: dict[str, AxisConfig]
    controller: ControllerSettings
    simulation: SimulationConfig = field(default_factory=SimulationConfig)
    hil: HilSettings = field(default_factory=HilSettings)
    accelerometer: AccelerometerConfig = field(default_factory=AccelerometerConfig)
    source: str = ""

    def _check(self) -> None:
        if tuple(sorted(self.axes)) != AXES:
            raise ConfigError("axes", f"must define exactly {AXES}, got {tuple(self.axes)}")
        # the twin advances whole drive intervals per controller period
        sim, period = self.simulation, self.controller.period
        drive = sim.timestep * sim.drive_substeps
        n = round(period / drive)
        if n < 1 or abs(n * drive - period) > 1e-9 * drive:
            raise ConfigError("controller.period", f"must be a whole number of the twin's "
                              f"drive intervals (simulation.timestep × "
                              f"simulation.drive_substeps = "
                              f"{sim.timestep:g} s × {sim.drive_substeps} = {drive:g} s), got "
                              f"{period:g} s")
        self._check_elastic_modes()

    def _check_elastic_modes(self) -> None:
        """The physics step must resolve each axis' fastest elastic mode
        (``TransmissionConfig.fastest_mode``: the chain of rotor, screw and moving mass,
        the X axis carrying the Y carriage, where the screw is stiffest). MuJoCo integrates
        the springs explicitly; with ω·timestep ≤ ELASTIC_STEP a period of the mode spans
        at least 2π/0.5 ≈ 12.6 steps (a longer step diverges, and a run would stop with a
        diverged plant). Also: the nut stays on its screw over the travel."""
        dt = self.simulation.timestep
        mass = self.moving_masses()
        for ax in AXES:
            a = self.axes[ax]
            tr, travel = a.transmission, a.mechanics.travel
            try:
                tr.check_travel(travel)
            except ConfigError as exc:
                raise ConfigError(f"axes.{ax}.transmission.{exc.field}", exc.message) from None
            k, j = tr.axial_stiffness, a.mechanics.rotor_inertia
            omega = tr.fastest_mode(mass[ax], j, travel)
            if omega * dt > ELASTIC_STEP:
                screw = (f", the screw body (axes.{ax}.transmission.screw_diameter, "
                         f"screw_length, nut_start)" if tr.screw_diameter > 0.0 else "")
                raise ConfigError(
                    "simulation.timestep", f"{dt:g} s is too long for the elastic mode of "
                    f"axis {ax}: ω = {omega:.4g} rad/s from axes.{ax}.transmission.stiffness "
                    f"({k:.4g} N/m in series), the moving mass {mass[ax]:g} kg "
                    f"(axes.{ax}.mechanics.carriage_mass"
                    + (", axes.y.mechanics.carriage_mass" if ax == "x" else "")
                    + f"){screw} and axes.{ax}.mechanics.rotor_inertia ({j:g} kg·m² through "
                    f"the axes.{ax}.transmission); it needs simulation.timestep <= "
                    f"{ELASTIC_STEP:g}/ω = {ELASTIC_STEP / omega:.3g} s")

    def moving_masses(self) -> dict[str, float]:
        """Mass moved by each axis of the cross table (kg): the Y carriage rides on the X
        one (``moving_masses``)."""
        return moving_masses(self.axes)

    def with_overrides(self, overrides: dict[str, Any]) -> MachineConfig:
        """A copy with dotted-path overrides applied and validated again.

        ``axes.*.x`` style keys apply to both axes. Unknown keys raise ``ConfigError``
        listing the valid keys at that level.
        """
        raw = copy.deepcopy(to_raw(self))
        for key, value in overrides.items():
            parts = key.split(".")
            if parts[0] == "axes" and len(parts) > 1 and parts[1] == "*":
                for ax in AXES:
                    set_path(raw, ["axes", ax, *parts[2:]], value, key)
            else:
                set_path(raw, parts, value, key)
        return machine_from_raw(raw, self.source)


def machine_from_raw(raw: dict[str, Any], source: str) -> MachineConfig:
    """A validated machine from its plain dict (the TOML's tables, axes merged), units in
    strings converted by the schema's own units."""
    cfg = from_dict(MachineConfig, raw, unit_of=field_unit)
    return dataclasses.replace(cfg, source=source)


def field_meta(path: str) -> dict[str, Any]:
    """The schema's metadata of the machine field at a dotted ``path`` (unit, bounds ``gt``,
    ``ge``, ``le`` and ``doc``; see :func:`range_text`); ``{}`` for a field without one (a
    string, a flag, a table) or an unknown path. A stiffness component's is its range."""
    import typing

    node: Any = MachineConfig
    parts = path.split(".")
    i = 0
    while i < len(parts):
        if not dataclasses.is_dataclass(node):
            return {}
        hints = typing.get_type_hints(node)
        f = next((f for f in dataclasses.fields(node) if f.name == parts[i]), None)
        if f is None:
            return {}
        if i == len(parts) - 1:
            return dict(f.metadata) if f.metadata else {}
        tp = hints[f.name]
        if typing.get_origin(tp) is dict:  # axes.<name>.…, stiffness.<name>
            value_type = typing.get_args(tp)[1]
            if i + 1 == len(parts) - 1:
                return (spec("N/m", ge=STIFFNESS_RANGE[0], le=STIFFNESS_RANGE[1],
                             doc="one component of the chain's stiffness, at the table "
                             "(gear, coupling: rotor to screw body; others: axial; screw: "
                             "where it is weakest over the travel)")
                        if f.name == "stiffness" else {})
            node, i = value_type, i + 2
            continue
        node, i = tp, i + 1
    return {}


def field_unit(path: str) -> str:
    """The unit of the machine field at a dotted ``path`` (``"axes.x.tacho.gain"`` →
    ``"V·s/rad"``), from the schema's metadata; ``""`` for a field without one (a string, a
    flag, a table) or an unknown path."""
    return str(field_meta(path).get("unit", ""))
