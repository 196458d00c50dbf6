"""The machine schema: frozen, validated dataclasses for every section of a machine file.

Every numeric field carries its unit and bounds in its metadata; ``__post_init__`` checks
them and raises ``ConfigError`` naming the field. Loading (TOML, dotted overrides) is in
``twin.config.loader``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from twin.errors import ConfigError

__all__ = [
    "AXES",
    "AxisConfig",
    "ControllerSettings",
    "ConverterConfig",
    "DacConfig",
    "DeadlineConfig",
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
    "TimingConfig",
    "TransmissionConfig",
    "field_meta",
    "field_unit",
    "range_text",
]

AXES = ("x", "y")


def _spec(unit: str, *, gt: float | None = None, ge: float | None = None,
          le: float | None = None, doc: str = "") -> dict[str, Any]:
    return {"unit": unit, "gt": gt, "ge": ge, "le": le, "doc": doc}


def _num(default: Any = dataclasses.MISSING, unit: str = "", *, gt: float | None = None,
         ge: float | None = None, le: float | None = None, doc: str = "") -> Any:
    """A numeric field with its unit and its physically meaningful range (checked on load;
    :func:`describe_field` states them)."""
    return field(default=default, metadata=_spec(unit, gt=gt, ge=ge, le=le, doc=doc))


ELASTIC_STEP = 0.5
"""Largest ω·timestep of an axis' elastic mode (see ``MachineConfig._check_elastic_modes``)."""

def _choice(default: Any, choices: tuple[Any, ...], doc: str) -> Any:
    """A field that takes one of ``choices`` (checked on load)."""
    return field(default=default, metadata={"choices": choices, "doc": doc})


def _flag(default: bool, doc: str) -> Any:
    """A true/false field."""
    return field(default=default, metadata={"choices": (True, False), "doc": doc})


PROFILES = ("trapezoid", "parabolic", "cosine", "cubic", "jerk-limited")
"""The acceleration laws (``twin.controller.profiles.laws.LAWS``; a test keeps them equal)."""

PLANNERS = ("lookahead", "stop")
"""The planner's modes (``twin.controller.planner.MODES``)."""

STIFFNESS_RANGE = (1e3, 1e11)
"""Range of each stiffness component of a transmission (N/m): a soft belt to a stiff
ball-screw assembly."""


def range_text(meta: Any) -> str:
    """The range of a numeric field as ``[lo, hi] unit`` (``(`` for an open end), or the
    choices of a field that takes one of them (``one of a, b``)."""
    if meta.get("choices"):
        return "one of " + ", ".join(
            str(c).lower() if isinstance(c, bool) else str(c) for c in meta["choices"])
    lo = f"({meta['gt']:g}" if meta.get("gt") is not None else (
        f"[{meta['ge']:g}" if meta.get("ge") is not None else "(-inf")
    hi = f"{meta['le']:g}]" if meta.get("le") is not None else "inf)"
    unit = meta.get("unit", "")
    return f"{lo}, {hi}" + (f" {unit}" if unit and unit != "1" else "")


def _leaves(value: Any) -> list[Any]:
    if isinstance(value, tuple | list):
        return [v for item in value for v in _leaves(item)]
    return [value]


class _Validated:
    """Mixin: check every numeric field against its metadata bounds after construction."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            meta = f.metadata
            choices = meta.get("choices")
            flag = choices == (True, False)
            if choices and value is not None and (value not in choices or (
                    flag and not isinstance(value, bool))):
                raise ConfigError(f.name, f"must be {range_text(meta)}, got {value!r}")
            if not meta or value is None or isinstance(value, bool):
                continue
            for v in _leaves(value):
                if not isinstance(v, int | float) or isinstance(v, bool):
                    continue
                inside = (math.isfinite(v)
                          and (meta.get("gt") is None or v > meta["gt"])
                          and (meta.get("ge") is None or v >= meta["ge"])
                          and (meta.get("le") is None or v <= meta["le"]))
                if not inside:
                    raise ConfigError(f.name, f"must lie in {range_text(meta)}, got {v:g}")
        self._check()

    def _check(self) -> None:
        """Cross-field checks; override."""


# --------------------------------------------------------------------------- mechanics
@dataclass(frozen=True, kw_only=True)
class MechanicsConfig(_Validated):
    """Moving masses, inertias, friction and travel of one axis."""

    carriage_mass: float = _num(unit="kg", ge=0.01, le=1e5,
                                doc="mass of this axis' carriage alone")
    travel: tuple[float, float] = _num(unit="m", ge=-10.0, le=10.0,
                                       doc="slide joint range (min, max)")
    slide_coulomb: float = _num(0.0, "N", ge=0, le=1e5, doc="Coulomb friction of the slide")
    slide_viscous: float = _num(0.0, "N·s/m", ge=0, le=1e7,
                                doc="viscous friction of the slide")
    rotor_inertia: float = _num(unit="kg·m²", ge=1e-7, le=10.0,
                                doc="motor rotor + gear, at the motor")
    rotor_coulomb: float = _num(0.0, "N·m", ge=0, le=1e3,
                                doc="Coulomb friction at the motor shaft")
    rotor_viscous: float = _num(0.0, "N·m·s/rad", ge=0, le=100.0,
                                doc="viscous friction at the motor")
    slide_breakaway: float = _num(
        0.0, "N", ge=0, le=1e5, doc="break-away (static) friction of the slide, >= "
        "slide_coulomb; 0 = none above Coulomb")
    rotor_breakaway: float = _num(
        0.0, "N·m", ge=0, le=1e3, doc="break-away friction at the motor shaft, >= "
        "rotor_coulomb; 0 = none above Coulomb")
    stribeck_velocity: float = _num(
        1e-3, "m/s", ge=1e-6, le=1.0, doc="table speed over which the break-away excess "
        "decays (Stribeck: exp(-(v/v_s)²)); the rotor's is this over the transmission ratio")

    def _check(self) -> None:
        if len(self.travel) != 2 or not self.travel[0] + 1e-3 <= self.travel[1]:
            raise ConfigError("travel", f"must be (min, max) with max at least 1 mm above "
                              f"min, got {self.travel}")
        for part in ("slide", "rotor"):
            brk, coul = getattr(self, f"{part}_breakaway"), getattr(self, f"{part}_coulomb")
            if 0.0 < brk < coul:
                raise ConfigError(f"{part}_breakaway", f"must be >= {part}_coulomb = {coul} "
                                  f"(or 0 for none), got {brk}")

    def breakaway(self, part: str) -> float:
        """Break-away friction of ``"slide"`` (N) or ``"rotor"`` (N·m): never below
        Coulomb (a value of 0 in the file means Coulomb alone)."""
        return max(getattr(self, f"{part}_breakaway"), getattr(self, f"{part}_coulomb"))


@dataclass(frozen=True, kw_only=True)
class TransmissionConfig(_Validated):
    """Motor → table transmission: a gear then a lead screw (or a belt pulley).

    The compliance of the whole chain is one linear spring (the ``x_screw`` tendon), the
    series combination of ``stiffness`` components (N/m, referred to the table).
    """

    kind: str = _choice("screw", ("screw", "belt"), "a lead screw, or a belt on a pulley")
    gear_ratio: float = _num(unit="1", ge=0.01, le=1000.0,
                             doc="motor revolutions per screw/pulley revolution")
    lead: float = _num(0.0, "m", ge=0, le=0.1,
                       doc="screw lead (kind = screw: at least 0.1 mm)")
    pulley_radius: float = _num(0.0, "m", ge=0, le=0.5,
                                doc="belt pulley pitch radius (kind = belt: at least 1 mm)")
    stiffness: dict[str, float] = field(default_factory=dict)
    damping_ratio: float = _num(unit="1", ge=1e-4, le=2,
                                doc="damping of the first elastic mode")
    backlash: float = _num(
        0.0, "m", ge=0, le=1e-3, doc="lost motion of gear and nut together, referred to the "
        "table, in series with the screw spring (a dead band of this width); 0 = none")

    def _check(self) -> None:
        if self.kind not in ("screw", "belt"):
            raise ConfigError("kind", f"must be 'screw' or 'belt', got {self.kind!r}")
        if self.kind == "screw" and not self.lead >= 1e-4:
            raise ConfigError("lead", f"must lie in [0.0001, 0.1] m for a screw "
                              f"transmission (kind = 'screw'), got {self.lead:g}")
        if self.kind == "belt" and not self.pulley_radius >= 1e-3:
            raise ConfigError("pulley_radius", f"must lie in [0.001, 0.5] m for a belt "
                              f"transmission (kind = 'belt'), got {self.pulley_radius:g}")
        if not self.stiffness:
            raise ConfigError("stiffness", "needs at least one component (N/m)")
        lo, hi = STIFFNESS_RANGE
        for name, k in self.stiffness.items():
            if not isinstance(k, int | float) or not math.isfinite(k) or not lo <= k <= hi:
                raise ConfigError(f"stiffness.{name}", f"must lie in [{lo:g}, {hi:g}] N/m, "
                                  f"got {k!r}")

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

    limit_min: float = _num(unit="m", ge=-10.0, le=10.0, doc="where the min end switch closes")
    limit_max: float = _num(unit="m", ge=-10.0, le=10.0, doc="where the max end switch closes")
    home: float = _num(unit="m", ge=-10.0, le=10.0, doc="where the home switch closes")
    debounce: float = _num(0.002, "s", ge=0, le=1.0, doc="a switch reads closed this long "
                           "after it closes")
    home_width: float = _num(0.5e-3, "m", ge=1e-6, le=0.1,
                             doc="the home switch is closed over this width")

    def _check(self) -> None:
        if not self.limit_min < self.home < self.limit_max:
            raise ConfigError("home", f"must lie between limit_min and limit_max: "
                              f"{self.limit_min:g} < {self.home:g} < {self.limit_max:g} m "
                              f"does not hold")


@dataclass(frozen=True, kw_only=True)
class EncoderConfig(_Validated):
    """Rotary encoder on the motor shaft and its hardware counter."""

    counts_per_rev: int = _num(2500, "1/rev", ge=1, le=10**8,
                               doc="counts per motor revolution (edges of both channels)")
    bits: int = _num(32, "bit", ge=8, le=64, doc="width of the hardware counter")
    noise_counts: float = _num(0.0, "count", ge=0, le=1e3, doc="rms sensor noise; 0 = off")


# --------------------------------------------------------------------------- drive
@dataclass(frozen=True, kw_only=True)
class MotorConfig(_Validated):
    """Separately excited DC motor (constant field)."""

    rated_voltage: float = _num(unit="V", ge=1.0, le=1e4, doc="rated armature voltage")
    rated_current: float = _num(unit="A", ge=0.01, le=1e4, doc="rated armature current")
    rated_speed_rpm: float = _num(unit="rev/min", ge=1.0, le=1e5, doc="rated speed")
    emf_constant: float = _num(unit="V·s/rad", ge=1e-4, le=100.0,
                               doc="k: back-EMF k·ω, torque k·i")
    armature_resistance: float = _num(unit="Ω", ge=1e-4, le=1e3,
                                      doc="armature circuit resistance")
    armature_inductance: float = _num(unit="H", ge=1e-6, le=10.0,
                                      doc="armature circuit inductance")
    current_limit_factor: float = _num(2.5, "1", ge=0.1, le=10.0,
                                       doc="current limit over rated current")

    def _check(self) -> None:
        emf = self.emf_constant * self.rated_speed
        if not 0.5 * self.rated_voltage <= emf <= 1.1 * self.rated_voltage:
            raise ConfigError("emf_constant", f"the back-EMF at the rated speed, emf_constant "
                              f"× rated_speed_rpm = {emf:.4g} V, must lie within 0.5 … 1.1 "
                              f"× rated_voltage ({self.rated_voltage:g} V): a motor's data "
                              f"are consistent, got emf_constant = {self.emf_constant:g} "
                              f"V·s/rad")

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
    """Power converter: a non-circulating pair of thyristor converters (6-pulse bridges or
    3-pulse midpoint circuits), or a PWM transistor bridge.

    ``model`` chooses how a thyristor converter is simulated: ``"pulse"`` (the default: the
    instantaneous voltage of the conducting pair, discontinuous conduction as the circuit
    gives it, :mod:`twin.drive.pulse`) or ``"mean"`` (the mean voltage of each firing
    period held constant). A PWM bridge is always ``"mean"``.
    """

    kind: str = _choice("thyristor", ("thyristor", "pwm"),
                        "a pair of thyristor converters, or a PWM transistor bridge")
    model: str | None = _choice(None, ("pulse", "mean"), "how a thyristor converter is "
                                "simulated: the conducting pair's voltage, or the mean of "
                                "each firing period; default pulse (thyristor), mean (pwm)")
    line_voltage: float = _num(100.0, "V", ge=1.0, le=1e4,
                               doc="thyristor: line-to-line rms U_LL")
    mains_frequency: float = _num(50.0, "Hz", ge=1.0, le=1e3, doc="frequency of the mains")
    mains_phase: float = _num(0.0, "rad", ge=0, le=2 * math.pi,
                              doc="phase of the mains at time 0 of the twin's clock")
    pulse_number: int = _num(6, "1", ge=3, le=6,
                             doc="6: three-phase bridge; 3: midpoint circuit")
    line_inductance: float = _num(
        0.0, "H", ge=0, le=0.1,
        doc="commutating inductance per phase (overlap); 0 = instantaneous")
    dcm_compensation: bool = _flag(True, "the current regulator adapts to discontinuous "
                                   "conduction")
    """Thyristor drives: the current regulator adapts to discontinuous conduction (the
    firing unit inverts the discontinuous characteristic; integral control per pulse)."""
    reversal_pause: float = _num(2e-3, "s", ge=0, le=0.1,
                                 doc="current-zero pause at bridge reversal")
    min_firing_angle: float = _num(0.0, "rad", ge=0, le=math.pi, doc="smallest firing angle")
    max_firing_angle: float = _num(math.radians(150.0), "rad", gt=0, le=math.pi,
                                   doc="largest firing angle (inverter limit)")
    dc_link_voltage: float = _num(0.0, "V", ge=0, le=1e4, doc="pwm: DC link voltage")
    pwm_frequency: float = _num(0.0, "Hz", ge=0, le=1e6, doc="pwm: switching frequency")

    def _check(self) -> None:
        if self.kind not in ("thyristor", "pwm"):
            raise ConfigError("kind", f"must be 'thyristor' or 'pwm', got {self.kind!r}")
        if self.kind == "pwm" and not self.dc_link_voltage >= 1.0:
            raise ConfigError("dc_link_voltage", f"must lie in [1, 10000] V for a pwm "
                              f"converter, got {self.dc_link_voltage:g}")
        if self.kind == "pwm" and not self.pwm_frequency >= 100.0:
            raise ConfigError("pwm_frequency", f"must lie in [100, 1e+06] Hz for a pwm "
                              f"converter, got {self.pwm_frequency:g}")
        if self.kind == "thyristor" and not self.min_firing_angle < self.max_firing_angle:
            raise ConfigError("max_firing_angle", "must exceed min_firing_angle")
        if self.kind == "thyristor" and self.pulse_number not in (3, 6):
            raise ConfigError("pulse_number", f"must be 6 (bridge) or 3 (midpoint circuit), "
                              f"got {self.pulse_number}")
        if self.model is None:
            object.__setattr__(self, "model", "pulse" if self.kind == "thyristor" else "mean")
        if self.model not in ("pulse", "mean"):
            raise ConfigError("model", f"must be 'pulse' or 'mean', got {self.model!r}")
        if self.kind == "pwm" and self.model != "mean":
            raise ConfigError("model", "a PWM converter is modelled by its mean voltage: "
                              "'mean'")

    @property
    def peak_voltage(self) -> float:
        """Û, peak of the voltage one conducting pair applies (V): √2·U_LL for the bridge,
        √2·U_LL/√3 (the phase voltage) for the midpoint circuit; the DC link for PWM."""
        if self.kind != "thyristor":
            return self.dc_link_voltage
        u = math.sqrt(2.0) * self.line_voltage
        return u if self.pulse_number == 6 else u / math.sqrt(3.0)

    @property
    def max_voltage(self) -> float:
        """Largest mean output voltage (V): U_d0 = (p/π)·sin(π/p)·Û (1.35·U_LL for the
        bridge, 0.675·U_LL for the midpoint circuit), or the DC link for PWM."""
        if self.kind == "thyristor":
            p = self.pulse_number
            return p / math.pi * math.sin(math.pi / p) * self.peak_voltage
        return self.dc_link_voltage

    @property
    def series_phases(self) -> int:
        """Line inductances in series with a conducting pair: 2 (bridge), 1 (midpoint)."""
        return 2 if self.pulse_number == 6 else 1

    @property
    def firing_period(self) -> float:
        """Time between firing instants (s): 1/(p·f) for a bridge, 1/f_pwm for PWM."""
        if self.kind == "thyristor":
            return 1.0 / (self.pulse_number * self.mains_frequency)
        return 1.0 / self.pwm_frequency


@dataclass(frozen=True, kw_only=True)
class TachoConfig(_Validated):
    """Tachogenerator on the motor shaft: U = K_C·ω, then a first-order filter."""

    gain: float = _num(unit="V·s/rad", ge=1e-5, le=10.0, doc="K_C")
    filter_time_constant: float = _num(1e-3, "s", ge=0, le=1.0,
                                       doc="first-order filter on the tacho signal; 0 = "
                                       "none, else at least 1e-5 s")
    noise: float = _num(0.0, "V", ge=0, le=10.0, doc="rms noise on the tacho signal; 0 = off")
    ripple: tuple[tuple[float, float], ...] = field(default=(), metadata={
        "doc": "tacho ripple: at most 4 [harmonic per revolution in (0, 1000], amplitude % "
               "in [0, 100)]"})
    """Ripple of the tacho EMF: ``[[harmonic, amplitude_percent], ...]`` (harmonic per
    revolution > 0, amplitude in % of K_C·ω, 0 ≤ a < 100; at most 4), e.g. ``[[1, 0.5],
    [20, 1.0]]`` for an eccentricity and a commutator ripple."""

    def _check(self) -> None:
        if 0.0 < self.filter_time_constant < 1e-5:
            raise ConfigError("filter_time_constant", f"must be 0 (no filter) or lie in "
                              f"[1e-05, 1] s, got {self.filter_time_constant:g}")
        if len(self.ripple) > 4:
            raise ConfigError("ripple", f"at most 4 harmonics, got {len(self.ripple)}")
        for k, (harmonic, amplitude) in enumerate(self.ripple):
            if not (math.isfinite(harmonic) and 0 < harmonic <= 1000):
                raise ConfigError(f"ripple[{k}]", f"harmonic must lie in (0, 1000] per "
                                  f"revolution, got {harmonic}")
            if not (math.isfinite(amplitude) and 0.0 <= amplitude < 100.0):
                raise ConfigError(f"ripple[{k}]", f"amplitude must lie in [0, 100) %, got "
                                  f"{amplitude}")


@dataclass(frozen=True, kw_only=True)
class DacConfig(_Validated):
    """The CNC's analog speed reference output."""

    bits: int = _num(12, "bit", ge=1, le=32, doc="resolution of the DAC")
    full_scale: float = _num(10.0, "V", ge=0.1, le=100.0, doc="output range is ±full_scale")
    offset: float = _num(0.0, "V", ge=-1.0, le=1.0, doc="the plant's DAC: output at code 0")
    gain_error: float = _num(0.0, "1", ge=-0.5, le=0.5,
                             doc="the plant's DAC: relative error of its gain")


@dataclass(frozen=True, kw_only=True)
class SpeedLoopConfig(_Validated):
    """Speed loop of the drive. The regulator constants are derived in code from the motor
    and converter by the tuning rules (modulus optimum for current, symmetric optimum for
    speed); only the design choices live here."""

    reference_filter: float | None = _num(
        None, "s", ge=0, le=1.0, doc="T1, filter on the speed reference; None: a²·T_σ (SO "
        "rule)")
    symmetric_optimum_a: float = _num(2.0, "1", ge=1.2, le=100.0,
                                      doc="SO spacing factor a (a=2: classic)")


@dataclass(frozen=True, kw_only=True)
class LimitsConfig(_Validated):
    """Kinematic limits of one axis (per-axis) or of the contour."""

    max_velocity: float = _num(unit="m/s", ge=1e-4, le=100.0, doc="largest speed")
    max_acceleration: float = _num(unit="m/s²", ge=1e-4, le=1e4, doc="largest acceleration")
    max_jerk: float = _num(unit="m/s³", ge=1e-3, le=1e7, doc="largest jerk")


@dataclass(frozen=True, kw_only=True)
class AxisConfig(_Validated):
    """Everything about one axis."""

    mechanics: MechanicsConfig
    transmission: TransmissionConfig
    switches: SwitchConfig
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    motor: MotorConfig
    converter: ConverterConfig = field(default_factory=ConverterConfig)
    tacho: TachoConfig
    dac: DacConfig = field(default_factory=DacConfig)
    speed_loop: SpeedLoopConfig = field(default_factory=SpeedLoopConfig)
    limits: LimitsConfig

    def _check(self) -> None:
        lo, hi = self.mechanics.travel
        for name in ("limit_min", "limit_max", "home"):
            pos = getattr(self.switches, name)
            if not lo <= pos <= hi:
                raise ConfigError(f"switches.{name}", f"must lie within mechanics.travel "
                                  f"[{lo:g}, {hi:g}] m, got {pos:g}")

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
    """Position regulator of both axes. ``None`` means: derive from the drive model.

    Each gain is one number for both axes or an ``[x, y]`` pair. ``dcu_alpha`` (``[[α1, α2,
    α3], [α1, α2, α3]]``, V/m, x then y) replaces the DCU that ``dcu_order`` would derive —
    what a tuning job writes (``twin tune`` → ``twin run --set-file``).
    """

    kp: float | tuple[float, float] | None = _num(None, "V/m", ge=0, le=1e7,
                                                  doc="proportional gain")
    ki: float | tuple[float, float] | None = _num(None, "V/(m·s)", ge=0, le=1e9,
                                                  doc="integral gain")
    kd: float | tuple[float, float] | None = _num(None, "V·s/m", ge=0, le=1e5,
                                                  doc="derivative gain")
    ff1: float | tuple[float, float] | None = _num(None, "V·s/m", ge=0, le=1e5,
                                                   doc="velocity feed-forward")
    ff2: float | tuple[float, float] | None = _num(None, "V·s²/m", ge=0, le=1e4,
                                                   doc="acceleration feed-forward")
    ff3: float | tuple[float, float] | None = _num(None, "V·s³/m", ge=0, le=1e3,
                                                   doc="jerk feed-forward")
    dcu_order: int = _num(0, "1", ge=0, le=3, doc="order of the derived DCU; 0 = off")
    dcu_alpha: tuple[tuple[float, float, float], tuple[float, float, float]] | None = _num(
        None, "V/m", ge=-1e9, le=1e9, doc="the DCU's coefficients, x then y")
    following_error_limit: float = _num(2e-3, "m", ge=1e-7, le=1.0,
                                        doc="a larger following error trips the axis")


@dataclass(frozen=True, kw_only=True)
class TimingConfig(_Validated):
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

    granularity: float = _num(0.0, "s", ge=0, le=1.0, doc="OS clock tick; 0 = exact")
    rearm: str = _choice("absolute", ("absolute", "relative"),
                         "a periodic timer, or one re-armed by its handler")
    late_probability: float = _num(0.0, "1", ge=0, le=1, doc="chance that a tick is late")
    late_max: float = _num(0.0, "s", ge=0, le=1.0, doc="a late tick comes up to this late")
    skip_probability: float = _num(0.0, "1", ge=0, le=1, doc="chance that a tick is lost")
    seed: int = _num(0, "1", ge=0, le=2**32 - 1, doc="seed of the timer's randomness")

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
class DeadlineConfig(_Validated):
    """What a paced run (real I/O) does about missed deadlines.

    A position loop that misses its periods is not controlling the machine: the run stops
    with a FAULT naming this policy when more than ``max_skipped_in_a_row`` consecutive
    periods are lost, or when, over the last ``window`` seconds, fewer than
    ``min_on_time`` of the periods started on time. A live warning comes first, once the
    on-time share falls below ``warn_on_time``.
    """

    max_skipped_in_a_row: int = _num(4, "periods", ge=0, le=1000,
                                     doc="more lost periods in a row stop the run")
    window: float = _num(1.0, "s", gt=0, le=600.0, doc="span of the on-time share")
    min_on_time: float = _num(0.9, "1", ge=0, le=1, doc="a lower on-time share stops the run")
    warn_on_time: float = _num(0.97, "1", ge=0, le=1,
                               doc="a lower on-time share is warned about")

    def _check(self) -> None:
        if self.warn_on_time < self.min_on_time:
            raise ConfigError("warn_on_time", f"must be >= min_on_time ({self.min_on_time}), "
                              f"got {self.warn_on_time}")


@dataclass(frozen=True, kw_only=True)
class ControllerSettings(_Validated):
    """The CNC: period, contour limits, planner and regulator settings."""

    period: float = _num(5e-3, "s", ge=1e-4, le=0.1, doc="the position loop's period")
    limits: LimitsConfig = field(
        default_factory=lambda: LimitsConfig(max_velocity=0.015, max_acceleration=0.2,
                                             max_jerk=5.0))
    rapid_velocity: float = _num(0.015, "m/s", ge=1e-4, le=100.0, doc="speed of G0 moves")
    contour_tolerance: float = _num(20e-6, "m", ge=1e-9, le=1.0,
                                    doc="largest deviation from the path at a corner (a "
                                    "study of corners without this limit sets 1 m)")
    profile: str = _choice("parabolic", PROFILES, "the acceleration law")
    planner: str = _choice("lookahead", PLANNERS, "look ahead over the blocks, or stop at "
                           "every node")
    lookahead: int = _num(64, "blocks", ge=1, le=100_000,
                          doc="blocks the planner looks ahead")
    soft_limits: bool = _flag(True, "refuse motion outside the work zone")
    """Refuse motion outside the work zone (the travel between the end switches)."""
    in_position_tolerance: float = _num(
        1e-6, "m", ge=1e-9, le=1e-3, doc="after the motion the loop stays closed until every "
        "axis' following error is within this (seed 000: 1 µm positioning accuracy)")
    settle_timeout: float = _num(2.0, "s", ge=1e-3, le=60.0,
                                 doc="longest wait for the in-position tolerance")
    min_feed: float = _num(1e-6, "m/s", ge=1e-9, le=1.0, doc="slowest programmed feed "
                           "accepted (0.06 mm/min): a slower F is refused at its line")
    max_program_time: float = _num(
        86400.0, "s", ge=1.0, le=3.2e7, doc="longest a program may take, judged by a lower "
        "bound (every move at its full feed, plus the dwells): beyond it the program is "
        "refused at the line that passes it")
    regulator: RegulatorSettings = field(default_factory=RegulatorSettings)
    timing: TimingConfig = field(default_factory=TimingConfig)
    deadlines: DeadlineConfig = field(default_factory=DeadlineConfig)


@dataclass(frozen=True, kw_only=True)
class SimulationConfig(_Validated):
    """Physics integration of the twin (chosen by the convergence test)."""

    timestep: float = _num(2e-4, "s", ge=1e-6, le=1e-2, doc="MuJoCo's time step")
    drive_substeps: int = _num(5, "1", ge=1, le=1000, doc="physics steps per drive update")
    seed: int = _num(0, "1", ge=0, le=2**32 - 1, doc="seed of the sensor noise")


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
        """The physics step must resolve each axis' fastest elastic mode: the screw spring
        between the moving mass (the X axis carries the Y carriage) and the rotor reflected
        to the table, ω² = k·(1/m + r²/J). MuJoCo integrates the spring explicitly; with
        ω·timestep ≤ ELASTIC_STEP a period of the mode spans at least 2π/0.5 ≈ 12.6 steps
        (a longer step diverges, and a run would stop with a diverged plant)."""
        dt = self.simulation.timestep
        mass = {"x": self.axes["x"].mechanics.carriage_mass
                + self.axes["y"].mechanics.carriage_mass,
                "y": self.axes["y"].mechanics.carriage_mass}
        for ax in AXES:
            a = self.axes[ax]
            k, r, j = a.transmission.axial_stiffness, a.transmission.ratio, \
                a.mechanics.rotor_inertia
            omega = math.sqrt(k * (1.0 / mass[ax] + r * r / j))
            if omega * dt > ELASTIC_STEP:
                raise ConfigError(
                    "simulation.timestep", f"{dt:g} s is too long for the elastic mode of "
                    f"axis {ax}: ω = {omega:.4g} rad/s from axes.{ax}.transmission.stiffness "
                    f"({k:.4g} N/m in series), the moving mass {mass[ax]:g} kg "
                    f"(axes.{ax}.mechanics.carriage_mass"
                    + (", axes.y.mechanics.carriage_mass" if ax == "x" else "")
                    + f") and axes.{ax}.mechanics.rotor_inertia ({j:g} kg·m² through the "
                    f"axes.{ax}.transmission); it needs simulation.timestep <= "
                    f"{ELASTIC_STEP:g}/ω = {ELASTIC_STEP / omega:.3g} s")

    def with_overrides(self, overrides: dict[str, Any]) -> MachineConfig:
        """A copy with dotted-path overrides applied and validated again.

        ``axes.*.x`` style keys apply to both axes. Unknown keys raise ``ConfigError``
        listing the valid keys at that level.
        """
        from twin.config.loader import _build, _set_path, _to_raw

        raw = copy.deepcopy(_to_raw(self))
        for key, value in overrides.items():
            parts = key.split(".")
            if parts[0] == "axes" and len(parts) > 1 and parts[1] == "*":
                for ax in AXES:
                    _set_path(raw, ["axes", ax, *parts[2:]], value, key)
            else:
                _set_path(raw, parts, value, key)
        return _build(raw, self.source)


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
                return (_spec("N/m", ge=STIFFNESS_RANGE[0], le=STIFFNESS_RANGE[1],
                              doc="one component of the series stiffness, at the table")
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
