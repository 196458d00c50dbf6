"""Machine parameter sets: TOML files validated into frozen dataclasses.

A machine file has ``[machine]``, ``[axis_defaults.*]`` (applied to both axes), ``[axes.x.*]``
and ``[axes.y.*]`` (per-axis overrides, deep-merged over the defaults), ``[controller.*]`` and
``[simulation]``. Every value is SI unless its name carries a unit suffix (``_rpm``). Every
error names the dotted field: ``axes.x.mechanics.carriage_mass: must be > 0, got -1``.

Typical use::

    cfg = load_machine("tomsk_xy")             # a preset in twin/machines/
    cfg = load_machine("my_machine.toml")      # or a path
    cfg = cfg.with_overrides({"controller.regulator.kp": 2000.0})
"""

from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twin.errors import ConfigError

__all__ = [
    "AXES",
    "MACHINES_DIR",
    "AxisConfig",
    "ControllerSettings",
    "ConverterConfig",
    "DacConfig",
    "EncoderConfig",
    "LimitsConfig",
    "MachineConfig",
    "MechanicsConfig",
    "MotorConfig",
    "RegulatorSettings",
    "SimulationConfig",
    "SpeedLoopConfig",
    "SwitchConfig",
    "TachoConfig",
    "TransmissionConfig",
    "available_machines",
    "from_dict",
    "load_machine",
]

AXES = ("x", "y")
MACHINES_DIR = Path(__file__).parent / "machines"


def _spec(unit: str, *, gt: float | None = None, ge: float | None = None,
          le: float | None = None, doc: str = "") -> dict[str, Any]:
    return {"unit": unit, "gt": gt, "ge": ge, "le": le, "doc": doc}


def _num(default: Any = dataclasses.MISSING, unit: str = "", *, gt: float | None = None,
         ge: float | None = None, le: float | None = None, doc: str = "") -> Any:
    """A numeric field with its unit and bounds (checked on load)."""
    return field(default=default, metadata=_spec(unit, gt=gt, ge=ge, le=le, doc=doc))


class _Validated:
    """Mixin: check every numeric field against its metadata bounds after construction."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            meta = f.metadata
            if not meta or value is None or isinstance(value, bool):
                continue
            values = value if isinstance(value, tuple) else (value,)
            for v in values:
                if not isinstance(v, int | float):
                    continue
                if not math.isfinite(v):
                    raise ConfigError(f.name, f"must be finite, got {v}")
                if meta.get("gt") is not None and not v > meta["gt"]:
                    raise ConfigError(f.name, f"must be > {meta['gt']}, got {v}")
                if meta.get("ge") is not None and not v >= meta["ge"]:
                    raise ConfigError(f.name, f"must be >= {meta['ge']}, got {v}")
                if meta.get("le") is not None and not v <= meta["le"]:
                    raise ConfigError(f.name, f"must be <= {meta['le']}, got {v}")
        self._check()

    def _check(self) -> None:
        """Cross-field checks; override."""


# --------------------------------------------------------------------------- mechanics
@dataclass(frozen=True, kw_only=True)
class MechanicsConfig(_Validated):
    """Moving masses, inertias, friction and travel of one axis."""

    carriage_mass: float = _num(unit="kg", gt=0, doc="mass of this axis' carriage alone")
    travel: tuple[float, float] = _num(unit="m", doc="slide joint range (min, max)")
    slide_coulomb: float = _num(0.0, "N", ge=0, doc="Coulomb friction of the slide")
    slide_viscous: float = _num(0.0, "N·s/m", ge=0, doc="viscous friction of the slide")
    rotor_inertia: float = _num(unit="kg·m²", gt=0, doc="motor rotor + gear, at the motor")
    rotor_coulomb: float = _num(0.0, "N·m", ge=0, doc="Coulomb friction at the motor shaft")
    rotor_viscous: float = _num(0.0, "N·m·s/rad", ge=0, doc="viscous friction at the motor")

    def _check(self) -> None:
        if len(self.travel) != 2 or not self.travel[0] < self.travel[1]:
            raise ConfigError("travel", f"must be (min, max) with min < max, got {self.travel}")


@dataclass(frozen=True, kw_only=True)
class TransmissionConfig(_Validated):
    """Motor → table transmission: a gear then a lead screw (or a belt pulley).

    The compliance of the whole chain is one linear spring (the ``x_screw`` tendon), the
    series combination of ``stiffness`` components (N/m, referred to the table).
    """

    kind: str = "screw"
    gear_ratio: float = _num(unit="1", gt=0, doc="motor revolutions per screw/pulley revolution")
    lead: float = _num(0.0, "m", ge=0, doc="screw lead (kind = screw)")
    pulley_radius: float = _num(0.0, "m", ge=0, doc="belt pulley pitch radius (kind = belt)")
    stiffness: dict[str, float] = field(default_factory=dict)
    damping_ratio: float = _num(unit="1", gt=0, le=2, doc="damping of the first elastic mode")

    def _check(self) -> None:
        if self.kind not in ("screw", "belt"):
            raise ConfigError("kind", f"must be 'screw' or 'belt', got {self.kind!r}")
        if self.kind == "screw" and self.lead <= 0:
            raise ConfigError("lead", "must be > 0 for a screw transmission")
        if self.kind == "belt" and self.pulley_radius <= 0:
            raise ConfigError("pulley_radius", "must be > 0 for a belt transmission")
        if not self.stiffness:
            raise ConfigError("stiffness", "needs at least one component (N/m)")
        for name, k in self.stiffness.items():
            if not isinstance(k, int | float) or not math.isfinite(k) or k <= 0:
                raise ConfigError(f"stiffness.{name}", f"must be a number > 0 (N/m), got {k!r}")

    @property
    def ratio(self) -> float:
        """Table travel per motor angle (m/rad)."""
        if self.kind == "screw":
            return self.lead / (2.0 * math.pi * self.gear_ratio)
        return self.pulley_radius / self.gear_ratio

    @property
    def axial_stiffness(self) -> float:
        """Series stiffness of all components (N/m)."""
        return 1.0 / sum(1.0 / k for k in self.stiffness.values())


@dataclass(frozen=True, kw_only=True)
class SwitchConfig(_Validated):
    """End limit switches and the home switch (table positions where they close)."""

    limit_min: float = _num(unit="m")
    limit_max: float = _num(unit="m")
    home: float = _num(unit="m")
    debounce: float = _num(0.002, "s", ge=0)
    home_width: float = _num(0.5e-3, "m", gt=0, doc="the home switch is closed over this width")

    def _check(self) -> None:
        if not self.limit_min < self.home < self.limit_max:
            raise ConfigError("home", "must lie between limit_min and limit_max")


@dataclass(frozen=True, kw_only=True)
class EncoderConfig(_Validated):
    """Rotary encoder on the motor shaft and its hardware counter."""

    counts_per_rev: int = _num(2500, "1/rev", gt=0)
    bits: int = _num(32, "bit", ge=8, le=64)
    noise_counts: float = _num(0.0, "count", ge=0, doc="rms sensor noise; 0 = off")


# --------------------------------------------------------------------------- drive
@dataclass(frozen=True, kw_only=True)
class MotorConfig(_Validated):
    """Separately excited DC motor (constant field)."""

    rated_voltage: float = _num(unit="V", gt=0)
    rated_current: float = _num(unit="A", gt=0)
    rated_speed_rpm: float = _num(unit="rev/min", gt=0)
    emf_constant: float = _num(unit="V·s/rad", gt=0, doc="k: back-EMF k·ω, torque k·i")
    armature_resistance: float = _num(unit="Ω", gt=0)
    armature_inductance: float = _num(unit="H", gt=0)
    current_limit_factor: float = _num(2.5, "1", gt=0, doc="current limit over rated current")

    @property
    def rated_speed(self) -> float:
        """Rated speed (rad/s)."""
        return self.rated_speed_rpm * 2.0 * math.pi / 60.0

    @property
    def current_limit(self) -> float:
        """Armature current limit (A)."""
        return self.current_limit_factor * self.rated_current


@dataclass(frozen=True, kw_only=True)
class ConverterConfig(_Validated):
    """Power converter: a 6-pulse thyristor bridge pair or a PWM transistor bridge."""

    kind: str = "thyristor"
    line_voltage: float = _num(100.0, "V", gt=0, doc="thyristor: line-to-line rms U_LL")
    mains_frequency: float = _num(50.0, "Hz", gt=0)
    pulse_number: int = _num(6, "1", gt=0)
    reversal_pause: float = _num(2e-3, "s", ge=0, doc="current-zero pause at bridge reversal")
    min_firing_angle: float = _num(0.0, "rad", ge=0, le=math.pi)
    max_firing_angle: float = _num(math.radians(150.0), "rad", gt=0, le=math.pi)
    dc_link_voltage: float = _num(0.0, "V", ge=0, doc="pwm: DC link voltage")
    pwm_frequency: float = _num(0.0, "Hz", ge=0, doc="pwm: switching frequency")

    def _check(self) -> None:
        if self.kind not in ("thyristor", "pwm"):
            raise ConfigError("kind", f"must be 'thyristor' or 'pwm', got {self.kind!r}")
        if self.kind == "pwm" and (self.dc_link_voltage <= 0 or self.pwm_frequency <= 0):
            raise ConfigError("dc_link_voltage", "pwm converter needs dc_link_voltage and "
                              "pwm_frequency > 0")
        if self.kind == "thyristor" and not self.min_firing_angle < self.max_firing_angle:
            raise ConfigError("max_firing_angle", "must exceed min_firing_angle")

    @property
    def max_voltage(self) -> float:
        """Largest mean output voltage (V): U_d0 = 1.35·U_LL, or the DC link for PWM."""
        if self.kind == "thyristor":
            return 3.0 * math.sqrt(2.0) / math.pi * self.line_voltage
        return self.dc_link_voltage

    @property
    def firing_period(self) -> float:
        """Time between firing instants (s): 1/(p·f) for a bridge, 1/f_pwm for PWM."""
        if self.kind == "thyristor":
            return 1.0 / (self.pulse_number * self.mains_frequency)
        return 1.0 / self.pwm_frequency


@dataclass(frozen=True, kw_only=True)
class TachoConfig(_Validated):
    """Tachogenerator on the motor shaft: U = K_C·ω, then a first-order filter."""

    gain: float = _num(unit="V·s/rad", gt=0, doc="K_C")
    filter_time_constant: float = _num(1e-3, "s", ge=0)
    noise: float = _num(0.0, "V", ge=0, doc="rms noise on the tacho signal; 0 = off")


@dataclass(frozen=True, kw_only=True)
class DacConfig(_Validated):
    """The CNC's analog speed reference output."""

    bits: int = _num(12, "bit", ge=1, le=32)
    full_scale: float = _num(10.0, "V", gt=0, doc="output range is ±full_scale")


@dataclass(frozen=True, kw_only=True)
class SpeedLoopConfig(_Validated):
    """Speed loop of the drive. The regulator constants are derived in code from the motor
    and converter by the tuning rules (modulus optimum for current, symmetric optimum for
    speed); only the design choices live here."""

    reference_filter: float | None = _num(
        None, "s", ge=0, doc="T1, filter on the speed reference; None: a²·T_σ (SO rule)")
    symmetric_optimum_a: float = _num(2.0, "1", gt=1, doc="SO spacing factor a (a=2: classic)")


@dataclass(frozen=True, kw_only=True)
class LimitsConfig(_Validated):
    """Kinematic limits of one axis (per-axis) or of the contour."""

    max_velocity: float = _num(unit="m/s", gt=0)
    max_acceleration: float = _num(unit="m/s²", gt=0)
    max_jerk: float = _num(unit="m/s³", gt=0)


@dataclass(frozen=True, kw_only=True)
class AxisConfig(_Validated):
    """Everything about one axis."""

    mechanics: MechanicsConfig
    transmission: TransmissionConfig
    switches: SwitchConfig
    encoder: EncoderConfig
    motor: MotorConfig
    converter: ConverterConfig
    tacho: TachoConfig
    dac: DacConfig
    speed_loop: SpeedLoopConfig
    limits: LimitsConfig

    @property
    def counts_per_metre(self) -> float:
        """Encoder counts per metre of table travel (counts/m)."""
        return self.encoder.counts_per_rev / (2.0 * math.pi * self.transmission.ratio)

    @property
    def volts_per_speed(self) -> float:
        """Speed reference that the drive turns into 1 m/s of table speed (V·s/m)."""
        return self.tacho.gain / self.transmission.ratio


# --------------------------------------------------------------------------- controller
@dataclass(frozen=True, kw_only=True)
class RegulatorSettings(_Validated):
    """Position regulator of both axes. ``None`` means: derive from the drive model."""

    kp: float | None = _num(None, "V/m", ge=0)
    ki: float | None = _num(None, "V/(m·s)", ge=0)
    kd: float | None = _num(None, "V·s/m", ge=0)
    ff1: float | None = _num(None, "V·s/m", ge=0, doc="velocity feed-forward")
    ff2: float | None = _num(None, "V·s²/m", ge=0, doc="acceleration feed-forward")
    ff3: float | None = _num(None, "V·s³/m", ge=0, doc="jerk feed-forward")
    dcu_order: int = _num(0, "1", ge=0, le=3)
    following_error_limit: float = _num(2e-3, "m", gt=0)


@dataclass(frozen=True, kw_only=True)
class ControllerSettings(_Validated):
    """The CNC: period, contour limits, planner and regulator settings."""

    period: float = _num(5e-3, "s", gt=0, le=0.1)
    limits: LimitsConfig = field(
        default_factory=lambda: LimitsConfig(max_velocity=0.015, max_acceleration=0.2,
                                             max_jerk=5.0))
    rapid_velocity: float = _num(0.015, "m/s", gt=0)
    contour_tolerance: float = _num(20e-6, "m", gt=0)
    profile: str = "parabolic"
    planner: str = "lookahead"
    lookahead: int = _num(64, "blocks", ge=1)
    regulator: RegulatorSettings = field(default_factory=RegulatorSettings)


@dataclass(frozen=True, kw_only=True)
class SimulationConfig(_Validated):
    """Physics integration of the twin (chosen by the convergence test)."""

    timestep: float = _num(2e-4, "s", gt=0, le=1e-2)
    drive_substeps: int = _num(5, "1", ge=1, doc="physics steps per drive update")
    seed: int = _num(0, "1", ge=0)


@dataclass(frozen=True, kw_only=True)
class MachineConfig(_Validated):
    """A whole machine: two axes, the controller's settings, the simulation settings."""

    name: str
    description: str
    axes: dict[str, AxisConfig]
    controller: ControllerSettings
    simulation: SimulationConfig = field(default_factory=SimulationConfig)
    source: str = ""

    def _check(self) -> None:
        if tuple(sorted(self.axes)) != AXES:
            raise ConfigError("axes", f"must define exactly {AXES}, got {tuple(self.axes)}")

    def with_overrides(self, overrides: dict[str, Any]) -> MachineConfig:
        """A copy with dotted-path overrides applied and validated again.

        ``axes.*.x`` style keys apply to both axes. Unknown keys raise ``ConfigError``
        listing the valid keys at that level.
        """
        raw = copy.deepcopy(self._raw)
        for key, value in overrides.items():
            parts = key.split(".")
            if parts[0] == "axes" and len(parts) > 1 and parts[1] == "*":
                for ax in AXES:
                    _set_path(raw, ["axes", ax, *parts[2:]], value, key)
            else:
                _set_path(raw, parts, value, key)
        return _build(raw, self.source)

    @property
    def _raw(self) -> dict[str, Any]:
        return _to_raw(self)


def _to_raw(obj: Any) -> Any:
    if dataclasses.is_dataclass(obj):
        return {f.name: _to_raw(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if f.name != "source"}
    if isinstance(obj, dict):
        return {k: _to_raw(v) for k, v in obj.items()}
    if isinstance(obj, tuple):
        return list(obj)
    return obj


def _set_path(raw: dict[str, Any], parts: list[str], value: Any, key: str) -> None:
    node: Any = raw
    for i, p in enumerate(parts[:-1]):
        if not isinstance(node, dict) or p not in node:
            valid = sorted(node) if isinstance(node, dict) else []
            raise ConfigError(key, f"unknown key {'.'.join(parts[: i + 1])!r}; "
                              f"valid here: {', '.join(valid)}")
        node = node[p]
    leaf = parts[-1]
    if not isinstance(node, dict) or (leaf not in node and not _open_dict(parts)):
        valid = sorted(node) if isinstance(node, dict) else []
        raise ConfigError(key, f"unknown key {key!r}; valid here: {', '.join(valid)}")
    node[leaf] = value


def _open_dict(parts: list[str]) -> bool:
    return len(parts) >= 2 and parts[-2] == "stiffness"


# --------------------------------------------------------------------------- loading
def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict) and k != "stiffness":
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _coerce(tp: Any, value: Any, path: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _coerce(args[0], value, path)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(path, f"must be a table, got {type(value).__name__}")
        return from_dict(tp, value, path)
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(path, f"must be a table, got {type(value).__name__}")
        _, vt = typing.get_args(tp)
        return {k: _coerce(vt, v, f"{path}.{k}") for k, v in value.items()}
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(path, f"must be an array, got {value!r}")
        args = typing.get_args(tp)
        if len(args) != len(value):
            raise ConfigError(path, f"must have {len(args)} items, got {len(value)}")
        pairs = enumerate(zip(args, value, strict=True))
        return tuple(_coerce(a, v, f"{path}[{i}]") for i, (a, v) in pairs)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(path, f"must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(path, f"must be finite, got {value}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(path, f"must be an integer, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(path, f"must be a string, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(path, f"must be true or false, got {value!r}")
        return value
    return value


def from_dict(cls: type, data: dict[str, Any], path: str = "") -> Any:
    """Build dataclass ``cls`` from a plain dict, naming the dotted field on any error."""
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    prefix = f"{path}." if path else ""
    for key in data:
        if key not in names:
            raise ConfigError(f"{prefix}{key}", f"unknown key; valid: {', '.join(sorted(names))}")
    kwargs = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        fpath = f"{prefix}{f.name}"
        if f.name in data:
            kwargs[f.name] = _coerce(hints[f.name], data[f.name], fpath)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(fpath, "missing")
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        if exc.field.startswith(prefix) and prefix:
            raise
        raise ConfigError(f"{prefix}{exc.field}", exc.message) from None


def _build(raw: dict[str, Any], source: str) -> MachineConfig:
    cfg = from_dict(MachineConfig, raw)
    return dataclasses.replace(cfg, source=source)


def available_machines() -> list[str]:
    """Names of the presets shipped in ``twin/machines``."""
    return sorted(p.stem for p in MACHINES_DIR.glob("*.toml"))


def load_machine(name_or_path: str | Path) -> MachineConfig:
    """Load and validate a machine by preset name or TOML path.

    Raises
    ------
    ConfigError
        If the file is missing, not valid TOML, or a field is missing or out of range.
    """
    p = Path(name_or_path)
    if not p.suffix and not p.exists():
        p = MACHINES_DIR / f"{name_or_path}.toml"
    if not p.is_file():
        raise ConfigError("machine", f"no machine file {str(name_or_path)!r}; presets: "
                          f"{', '.join(available_machines())}")
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(p), f"invalid TOML: {exc}") from None
    return machine_from_toml_dict(doc, source=str(p))


def machine_from_toml_dict(doc: dict[str, Any], *, source: str = "<dict>") -> MachineConfig:
    """Validate a parsed machine document (``[machine]``, ``[axis_defaults]``, ``[axes]``...)."""
    doc = copy.deepcopy(doc)
    head = doc.pop("machine", None)
    if not isinstance(head, dict) or "name" not in head:
        raise ConfigError("machine.name", "missing")
    defaults = doc.pop("axis_defaults", {})
    axes_over = doc.pop("axes", {})
    if not isinstance(axes_over, dict):
        raise ConfigError("axes", "must be a table")
    for ax in axes_over:
        if ax not in AXES:
            raise ConfigError(f"axes.{ax}", f"unknown axis; valid: {', '.join(AXES)}")
    raw: dict[str, Any] = {
        "name": head["name"],
        "description": head.get("description", ""),
        "axes": {ax: _deep_merge(defaults, axes_over.get(ax, {})) for ax in AXES},
        **doc,
    }
    return _build(raw, source)
