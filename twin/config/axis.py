"""The sections of one axis in a machine file: mechanics, transmission, switches, encoder,
motor, converter, tacho, DAC, speed loop, the drive's regulator settings and limits (each
field with its unit and physical range, ``twin.config.fields``), and ``AxisConfig``, which
gathers them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from twin.config.fields import Validated, choice, flag, num
from twin.errors import ConfigError

__all__ = ["STIFFNESS_RANGE", "AxisConfig", "ConverterConfig", "DacConfig", "EncoderConfig",
           "LimitsConfig", "MechanicsConfig", "MotorConfig", "RegulatorsConfig",
           "SpeedLoopConfig", "SwitchConfig", "TachoConfig", "TransmissionConfig"]

STIFFNESS_RANGE = (1e3, 1e11)
"""Range of each stiffness component of a transmission (N/m): a soft belt to a stiff
ball-screw assembly."""



# --------------------------------------------------------------------------- mechanics
@dataclass(frozen=True, kw_only=True)
class MechanicsConfig(Validated):
    """Moving masses, inertias, friction and travel of one axis."""

    carriage_mass: float = num(unit="kg", ge=0.01, le=1e5,
                               doc="mass of this axis' carriage alone")
    travel: tuple[float, float] = num(unit="m", ge=-10.0, le=10.0,
                                      doc="slide joint range (min, max)")
    slide_coulomb: float = num(0.0, "N", ge=0, le=1e5, doc="Coulomb friction of the slide")
    slide_viscous: float = num(0.0, "N·s/m", ge=0, le=1e7,
                               doc="viscous friction of the slide")
    rotor_inertia: float = num(unit="kg·m²", ge=1e-7, le=10.0,
                               doc="motor rotor + gear, at the motor")
    rotor_coulomb: float = num(0.0, "N·m", ge=0, le=1e3,
                               doc="Coulomb friction at the motor shaft")
    rotor_viscous: float = num(0.0, "N·m·s/rad", ge=0, le=100.0,
                               doc="viscous friction at the motor")
    slide_breakaway: float = num(
        0.0, "N", ge=0, le=1e5, doc="break-away (static) friction of the slide, >= "
        "slide_coulomb; 0 = none above Coulomb")
    rotor_breakaway: float = num(
        0.0, "N·m", ge=0, le=1e3, doc="break-away friction at the motor shaft, >= "
        "rotor_coulomb; 0 = none above Coulomb")
    stribeck_velocity: float = num(
        1e-3, "m/s", display="mm/s", ge=1e-6, le=1.0,
        doc="table speed over which the break-away excess "
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
class TransmissionConfig(Validated):
    """Motor → table transmission: a gear then a lead screw (or a belt pulley).

    The ``stiffness`` components (N/m, referred to the table) make up the chain's
    compliance. Without a screw body (``screw_diameter = 0``) the chain is one spring
    between the rotor and the table, the series combination of every component: the
    two-mass model. With one, the screw shaft is an inertia of its own between two springs
    (the three-mass model): the ``TORSIONAL`` components (gear stage, coupling) between
    rotor and screw, all others (screw shaft, nut, thrust bearing) axially between screw
    and table.

    With ``nut_start > 0`` the ``screw`` component varies with a, the nut's distance from
    the drive-end bearing: E·A/a (``fixed-free``) or E·A·L/(a·(L − a)) (``fixed-fixed``,
    L = ``screw_length``). The file's value is quoted where the screw is weakest within
    the travel (``fixed-free``: the far end), the constant a two-mass file uses
    everywhere. ``twin/models/README.md`` derives the numbers.
    """

    TORSIONAL = ("gear", "coupling")  # a class constant (no annotation: not a field)
    """Stiffness components between the rotor and a screw body; all others are axial."""
    STEEL_DENSITY = 7850.0
    """ρ of the screw shaft (kg/m³)."""

    kind: str = choice("screw", ("screw", "belt"), "a lead screw, or a belt on a pulley")
    gear_ratio: float = num(unit="1", ge=0.01, le=1000.0,
                            doc="motor revolutions per screw/pulley revolution")
    lead: float = num(0.0, "m", ge=0, le=0.1,
                      doc="screw lead (kind = screw: at least 0.1 mm)")
    pulley_radius: float = num(0.0, "m", ge=0, le=0.5,
                               doc="belt pulley pitch radius (kind = belt: at least 1 mm)")
    stiffness: dict[str, float] = field(default_factory=dict)
    damping_ratio: float = num(unit="1", ge=1e-4, le=2,
                               doc="damping of the first elastic mode")
    backlash: float = num(
        0.0, "m", display="µm", ge=0, le=1e-3,
        doc="lost motion of gear and nut together, referred to the "
        "table, in series with the screw spring (a dead band of this width); 0 = none")
    screw_diameter: float = num(
        0.0, "m", ge=0, le=0.2,
        doc="screw shaft diameter, for its inertia ρ·π·d⁴·L/32 (steel); 0 = no screw body "
        "(screw lumped with the rotor: the two-mass model), else at least 2 mm")
    screw_length: float = num(
        0.0, "m", ge=0, le=10.0,
        doc="screw shaft length: its inertia, and the span between its bearings "
        "(fixed-fixed); needed with screw_diameter or nut_start")
    screw_support: str = choice(
        "fixed-free", ("fixed-free", "fixed-fixed"), "axial supports of the screw: a "
        "thrust bearing at the drive end only, or at both ends")
    nut_start: float = num(
        0.0, "m", ge=0, le=10.0,
        doc="distance from the drive-end bearing to the nut with the table at the travel "
        "end nearest it (drive_end); 0 = the screw's stiffness does not vary with the nut")
    drive_end: str = choice("min", ("min", "max"), "the end of the travel nearest the "
                            "screw's drive-end bearing")

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
        self._check_screw()

    def _check_screw(self) -> None:
        """The screw's geometry: for a screw only, complete, and a screw body between two
        springs."""
        given = [n for n in ("screw_diameter", "screw_length", "nut_start")
                 if getattr(self, n) > 0.0]
        if self.kind != "screw" and given:
            raise ConfigError(given[0], f"only for a screw transmission (kind = 'screw'), "
                              f"got {getattr(self, given[0]):g} m")
        if 0.0 < self.screw_diameter < 2e-3:
            raise ConfigError("screw_diameter", f"must be 0 (no screw body) or lie in "
                              f"[0.002, 0.2] m, got {self.screw_diameter:g}")
        needs = [n for n in ("screw_diameter", "nut_start") if getattr(self, n) > 0.0]
        if needs and not self.screw_length >= 0.01:
            raise ConfigError("screw_length", f"must lie in [0.01, 10] m with {needs[0]} "
                              f"given, got {self.screw_length:g}")
        if self.nut_start > 0.0 and not self.nut_start < self.screw_length:
            raise ConfigError("nut_start", f"must be less than screw_length "
                              f"({self.screw_length:g} m), got {self.nut_start:g}")
        if self.nut_start > 0.0 and "screw" not in self.stiffness:
            raise ConfigError("stiffness", "nut_start makes the 'screw' component vary with "
                              "the nut position: it needs a 'screw' component, got "
                              f"{sorted(self.stiffness)}")
        if self.screw_diameter > 0.0:
            torsional = [n for n in self.stiffness if n in self.TORSIONAL]
            if not torsional or len(torsional) == len(self.stiffness):
                raise ConfigError("stiffness", "a screw body (screw_diameter > 0) sits "
                                  "between two springs: it needs a torsional component ("
                                  + " or ".join(self.TORSIONAL) + ") and an axial one "
                                  f"(screw, nut, bearing, ...), got {sorted(self.stiffness)}")

    def check_travel(self, travel: tuple[float, float]) -> None:
        """Check that the nut stays on the screw over ``travel`` (m): at the far end of
        travel it is ``nut_start`` + the travel from the drive-end bearing, which must be
        less than ``screw_length``.

        Raises
        ------
        ConfigError
            Naming ``screw_length`` (relative to this section).
        """
        if self.nut_start <= 0.0:
            return
        far = self.nut_start + (travel[1] - travel[0])
        if not far < self.screw_length:
            raise ConfigError("screw_length", f"must exceed nut_start + the length of "
                              f"mechanics.travel = {self.nut_start:g} + "
                              f"{travel[1] - travel[0]:g} = {far:g} m (the nut's distance "
                              f"from the drive-end bearing at the far end of travel), got "
                              f"{self.screw_length:g}")

    @property
    def ratio(self) -> float:
        """Table travel per motor angle (m/rad)."""
        if self.kind == "screw":
            return self.lead / (2.0 * math.pi * self.gear_ratio)
        return self.pulley_radius / self.gear_ratio

    @property
    def axial_stiffness(self) -> float:
        """Series stiffness of all components as the file gives them (N/m): the whole
        chain's static stiffness with the nut where the screw is weakest."""
        return 1.0 / sum(1.0 / k for k in self.stiffness.values())

    @property
    def screw_ratio(self) -> float:
        """Table travel per screw angle, lead/2π (m/rad); 0 for a belt."""
        return self.lead / (2.0 * math.pi) if self.kind == "screw" else 0.0

    @property
    def screw_inertia(self) -> float:
        """Rotational inertia of the screw shaft, J_s = ρ·π·d⁴·L/32 (kg·m²); 0 without a
        screw body."""
        d = self.screw_diameter
        if d <= 0.0:
            return 0.0
        return self.STEEL_DENSITY * math.pi * d**4 * self.screw_length / 32.0

    @property
    def gear_stiffness(self) -> float:
        """The spring between the rotor and a screw body: the ``TORSIONAL`` components in
        series, referred to the table (N/m); ``inf`` without a screw body (every component
        is then in the one spring of :meth:`spring_stiffness`)."""
        if self.screw_diameter <= 0.0:
            return math.inf
        return 1.0 / sum(1.0 / k for n, k in self.stiffness.items() if n in self.TORSIONAL)

    def nut_distance(self, position: float, travel: tuple[float, float]) -> float:
        """The nut's distance from the drive-end bearing with the table at ``position``
        (m) of the axis' ``travel`` (m); ``nan`` without ``nut_start``."""
        if self.nut_start <= 0.0:
            return math.nan
        moved = position - travel[0] if self.drive_end == "min" else travel[1] - position
        return self.nut_start + moved

    def screw_shape(self, distance: float) -> float:
        """g(a) of the screw's axial stiffness E·A/g(a) with the nut at ``distance`` a from
        the drive-end bearing (m): a (fixed-free), a·(L − a)/L (fixed-fixed)."""
        if self.screw_support == "fixed-free":
            return distance
        return distance * (self.screw_length - distance) / self.screw_length

    def reference_position(self, travel: tuple[float, float]) -> float:
        """The table position (m) at which ``stiffness.screw`` is quoted: where the screw
        is weakest within ``travel`` (the largest g(a)); ``nan`` without ``nut_start``."""
        if self.nut_start <= 0.0:
            return math.nan
        span = travel[1] - travel[0]
        if self.screw_support == "fixed-free":
            a = self.nut_start + span
        else:
            a = min(max(0.5 * self.screw_length, self.nut_start), self.nut_start + span)
        moved = a - self.nut_start
        return travel[0] + moved if self.drive_end == "min" else travel[1] - moved

    def spring_stiffness(self, position: float | None,
                         travel: tuple[float, float]) -> tuple[float, float]:
        """(gear spring, axial spring) stiffness (N/m, referred to the table) with the
        table at ``position`` (m) of ``travel`` (m); ``None``: the file's values.

        Without a screw body the gear spring is ``inf`` and the axial one is the whole
        chain (:attr:`axial_stiffness` when nothing varies); with one, the gear spring
        holds the ``TORSIONAL`` components and the axial one the rest. The ``screw``
        component scales as g(a_ref)/g(a) when ``nut_start`` is given (class docstring).
        """
        body = self.screw_diameter > 0.0
        varies = position is not None and self.nut_start > 0.0
        if not (body or varies):
            return math.inf, self.axial_stiffness
        compliance = 0.0
        for name, k in self.stiffness.items():
            if body and name in self.TORSIONAL:
                continue
            if name == "screw" and varies:
                ref = self.screw_shape(self.nut_distance(self.reference_position(travel),
                                                         travel))
                compliance += self.screw_shape(self.nut_distance(position, travel)) / (k * ref)
            else:
                compliance += 1.0 / k
        return self.gear_stiffness, 1.0 / compliance

    def fastest_mode(self, moving_mass: float, rotor_inertia: float,
                     travel: tuple[float, float]) -> float:
        """The highest elastic mode of the chain with a free rotor (rad/s), at the nut
        position of travel where the axial spring is stiffest: what the physics step must
        resolve (``MachineConfig`` checks it). Two-mass: √(k·(1/m + r²/J)); three-mass:
        the largest eigenvalue of the rotor–screw–table chain."""
        stiff = max((self.spring_stiffness(p, travel) for p in travel), key=lambda s: s[1])
        k_gear, k = stiff
        if self.screw_diameter <= 0.0:
            r = self.ratio
            return math.sqrt(k * (1.0 / moving_mass + r * r / rotor_inertia))
        import numpy as np

        mass = np.array([rotor_inertia / self.ratio**2,
                         self.screw_inertia / self.screw_ratio**2, moving_mass])
        chain = np.array([[k_gear, -k_gear, 0.0], [-k_gear, k_gear + k, -k], [0.0, -k, k]])
        scaled = chain / np.sqrt(np.outer(mass, mass))
        return math.sqrt(float(np.linalg.eigvalsh(scaled)[-1]))


@dataclass(frozen=True, kw_only=True)
class SwitchConfig(Validated):
    """End limit switches and the home switch (table positions where they close)."""

    limit_min: float = num(unit="m", ge=-10.0, le=10.0, doc="where the min end switch closes")
    limit_max: float = num(unit="m", ge=-10.0, le=10.0, doc="where the max end switch closes")
    home: float = num(unit="m", ge=-10.0, le=10.0, doc="where the home switch closes")
    debounce: float = num(0.002, "s", ge=0, le=1.0, doc="a switch reads closed this long "
                          "after it closes")
    home_width: float = num(0.5e-3, "m", ge=1e-6, le=0.1,
                            doc="the home switch is closed over this width")

    def _check(self) -> None:
        if not self.limit_min < self.home < self.limit_max:
            raise ConfigError("home", f"must lie between limit_min and limit_max: "
                              f"{self.limit_min:g} < {self.home:g} < {self.limit_max:g} m "
                              f"does not hold")


@dataclass(frozen=True, kw_only=True)
class EncoderConfig(Validated):
    """Rotary encoder on the motor shaft and its hardware counter."""

    counts_per_rev: int = num(2500, "1/rev", ge=1, le=10**8,
                              doc="counts per motor revolution (edges of both channels)")
    bits: int = num(32, "bit", ge=8, le=64, doc="width of the hardware counter")
    noise_counts: float = num(0.0, "count", ge=0, le=1e3, doc="rms sensor noise; 0 = off")


# --------------------------------------------------------------------------- drive
@dataclass(frozen=True, kw_only=True)
class MotorConfig(Validated):
    """Separately excited DC motor (constant field)."""

    rated_voltage: float = num(unit="V", ge=1.0, le=1e4, doc="rated armature voltage")
    rated_current: float = num(unit="A", ge=0.01, le=1e4, doc="rated armature current")
    rated_speed_rpm: float = num(unit="rev/min", ge=1.0, le=1e5, doc="rated speed")
    emf_constant: float = num(unit="V·s/rad", ge=1e-4, le=100.0,
                              doc="k: back-EMF k·ω, torque k·i")
    armature_resistance: float = num(unit="Ω", ge=1e-4, le=1e3,
                                     doc="armature circuit resistance")
    armature_inductance: float = num(unit="H", ge=1e-6, le=10.0,
                                     doc="armature circuit inductance")
    current_limit_factor: float = num(2.5, "1", ge=0.1, le=10.0,
                                      doc="current limit over rated current")
    brush_drop: float = num(0.0, "V", ge=0, le=10.0,
                            doc="brush contact drop, both brushes together, against the "
                            "current while it flows (1-2 V for carbon brushes); 0 = none")

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
class ConverterConfig(Validated):
    """Power converter: a non-circulating pair of thyristor converters (6-pulse bridges or
    3-pulse midpoint circuits), or a PWM transistor bridge.

    ``model`` chooses how a thyristor converter is simulated: ``"pulse"`` (the default: the
    instantaneous voltage of the conducting pair, discontinuous conduction as the circuit
    gives it, :mod:`twin.drive.pulse`) or ``"mean"`` (the mean voltage of each firing
    period held constant). A PWM bridge is always ``"mean"``.
    """

    kind: str = choice("thyristor", ("thyristor", "pwm"),
                       "a pair of thyristor converters, or a PWM transistor bridge")
    model: str | None = choice(None, ("pulse", "mean"), "how a thyristor converter is "
                               "simulated: the conducting pair's voltage, or the mean of "
                               "each firing period; default pulse (thyristor), mean (pwm)")
    line_voltage: float = num(100.0, "V", ge=1.0, le=1e4,
                              doc="thyristor: line-to-line rms U_LL")
    mains_frequency: float = num(50.0, "Hz", ge=1.0, le=1e3, doc="frequency of the mains")
    mains_phase: float = num(0.0, "rad", ge=0, le=2 * math.pi,
                             doc="phase of the mains at time 0 of the twin's clock")
    pulse_number: int = num(6, "1", ge=3, le=6,
                            doc="6: three-phase bridge; 3: midpoint circuit")
    line_inductance: float = num(
        0.0, "H", ge=0, le=0.1,
        doc="commutating inductance per phase (overlap); 0 = instantaneous")
    dcm_compensation: bool = flag(True, "the current regulator adapts to discontinuous "
                                  "conduction")
    """Thyristor drives: the current regulator adapts to discontinuous conduction (the
    firing unit inverts the discontinuous characteristic; integral control per pulse)."""
    reversal_pause: float = num(2e-3, "s", ge=0, le=0.1,
                                doc="current-zero pause at bridge reversal")
    min_firing_angle: float = num(0.0, "rad", ge=0, le=math.pi,
                                  doc="smallest firing angle (real drives: 10-30°)")
    max_firing_angle: float = num(math.radians(150.0), "rad", gt=0, le=math.pi,
                                  doc="largest firing angle, the inverter limit (about 150°)")
    thyristor_threshold: float = num(0.0, "V", ge=0, le=5.0,
                                     doc="on-state threshold voltage of one thyristor "
                                     "(about 0.8-1.2 V); 0 = none")
    thyristor_resistance: float = num(0.0, "Ω", ge=0, le=10.0,
                                      doc="on-state slope resistance of one thyristor; 0 = "
                                      "none")
    latching_current: float = num(0.0, "A", ge=0, le=10.0,
                                  doc="a fired thyristor stays on after its gate pulse only "
                                  "if its current reached this; 0 = always")
    holding_current: float = num(0.0, "A", ge=0, le=10.0,
                                 doc="without gate current a thyristor turns off when its "
                                 "current falls below this (<= latching_current); 0 = at zero")
    gate_pulse_width: float = num(0.0, "s", ge=0, le=0.02,
                                  doc="length of each firing's gate pulse; 0 = long pulses, "
                                  "on until the next firing")
    smoothing_inductance: float = num(0.0, "H", ge=0, le=1.0,
                                      doc="smoothing reactor in series with the armature; 0 "
                                      "= none")
    mains_deviation: float = num(0.0, "1", ge=-0.3, le=0.3,
                                 doc="relative deviation of the actual mains voltage from "
                                 "line_voltage (the plant's; the regulators do not know it)")
    dc_link_voltage: float = num(0.0, "V", ge=0, le=1e4, doc="pwm: DC link voltage")
    pwm_frequency: float = num(0.0, "Hz", ge=0, le=1e6, doc="pwm: switching frequency")

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
            raise ConfigError("min_firing_angle", f"must be below max_firing_angle "
                              f"({math.degrees(self.max_firing_angle):.4g}°), got "
                              f"{math.degrees(self.min_firing_angle):.4g}°")
        if self.holding_current > self.latching_current:
            raise ConfigError("holding_current", f"must not exceed latching_current "
                              f"({self.latching_current:g} A): a thyristor's latching "
                              f"current is at least its holding current, got "
                              f"{self.holding_current:g} A")
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
    def series_devices(self) -> int:
        """Thyristors in series with the armature while a pair conducts: 2 (bridge), 1
        (midpoint circuit); a PWM bridge: 0 (its drops are not modelled)."""
        if self.kind != "thyristor":
            return 0
        return 2 if self.pulse_number == 6 else 1

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
class TachoConfig(Validated):
    """Tachogenerator on the motor shaft: U = K_C·ω, then a first-order filter."""

    gain: float = num(unit="V·s/rad", ge=1e-5, le=10.0, doc="K_C")
    filter_time_constant: float = num(1e-3, "s", ge=0, le=1.0,
                                      doc="first-order filter on the tacho signal; 0 = "
                                      "none, else at least 1e-5 s")
    noise: float = num(0.0, "V", ge=0, le=10.0, doc="rms noise on the tacho signal; 0 = off")
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
class DacConfig(Validated):
    """The CNC's analog speed reference output."""

    bits: int = num(12, "bit", ge=1, le=32, doc="resolution of the DAC")
    full_scale: float = num(10.0, "V", ge=0.1, le=100.0, doc="output range is ±full_scale")
    offset: float = num(0.0, "V", ge=-1.0, le=1.0, doc="the plant's DAC: output at code 0")
    gain_error: float = num(0.0, "1", ge=-0.5, le=0.5,
                            doc="the plant's DAC: relative error of its gain")


@dataclass(frozen=True, kw_only=True)
class SpeedLoopConfig(Validated):
    """Speed loop of the drive: the design choices. The regulator constants are derived in
    code from the motor and converter by the tuning rules (modulus optimum for current,
    symmetric optimum for speed) unless the ``regulators`` section sets them."""

    reference_filter: float | None = num(
        None, "s", ge=0, le=1.0, doc="T1, filter on the speed reference; None: a²·T_σ (SO "
        "rule)")
    symmetric_optimum_a: float = num(2.0, "1", ge=1.2, le=100.0,
                                     doc="SO spacing factor a (a=2: classic)")


IMPLEMENTATIONS = ("digital", "analog")
"""How the drive's regulators are built (``RegulatorsConfig.implementation``)."""


@dataclass(frozen=True, kw_only=True)
class RegulatorsConfig(Validated):
    """How the drive on the machine is actually set: its current and speed PI regulators.

    Each gain or integral time left out (None) is the value ``twin.drive.design`` derives
    (modulus optimum for the current loop, symmetric optimum for the speed loop); a value
    given replaces that one value only, as a potentiometer set at commissioning does.
    ``implementation`` says how the regulators are built: ``"digital"`` (sampled at the
    firing instants, the current measured as the pulse mean) or ``"analog"`` (op-amp PI
    regulators that integrate continuously, the current measured through a shunt and an RC
    filter of ``current_filter``; the firing unit takes the control voltage at each firing).
    """

    current_kp: float | None = num(None, "V/A", gt=0, le=1e4,
                                   doc="current regulator gain; None: L/(2·T_μ) (modulus "
                                   "optimum)")
    current_ti: float | None = num(None, "s", gt=0, le=10.0,
                                   doc="current regulator integral time; None: L/R")
    speed_kp: float | None = num(None, "A/V", gt=0, le=1e4,
                                 doc="speed regulator gain; None: J/(a·T_σ·K_C·k) "
                                 "(symmetric optimum)")
    speed_ti: float | None = num(None, "s", gt=0, le=100.0,
                                 doc="speed regulator integral time; None: a²·T_σ")
    implementation: str = choice("digital", IMPLEMENTATIONS,
                                 "digital: sampled at the firing instants, pulse-mean "
                                 "current; analog: continuous op-amp PI, current through a "
                                 "shunt and an RC filter")
    current_filter: float = num(1e-3, "s", ge=0, le=0.1,
                                doc="analog: RC filter on the shunt's current signal; 0 = "
                                "none")


@dataclass(frozen=True, kw_only=True)
class LimitsConfig(Validated):
    """Kinematic limits of one axis (per-axis) or of the contour."""

    max_velocity: float = num(unit="m/s", ge=1e-4, le=100.0, doc="largest speed")
    max_acceleration: float = num(unit="m/s²", ge=1e-4, le=1e4, doc="largest acceleration")
    max_jerk: float = num(unit="m/s³", ge=1e-3, le=1e7, doc="largest jerk")


@dataclass(frozen=True, kw_only=True)
class AxisConfig(Validated):
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
    regulators: RegulatorsConfig = field(default_factory=RegulatorsConfig)
    limits: LimitsConfig

    def _check(self) -> None:
        self._check_drive()
        lo, hi = self.mechanics.travel
        for name in ("limit_min", "limit_max", "home"):
            pos = getattr(self.switches, name)
            if not lo <= pos <= hi:
                raise ConfigError(f"switches.{name}", f"must lie within mechanics.travel "
                                  f"[{lo:g}, {hi:g}] m, got {pos:g}")

    def _check_drive(self) -> None:
        """What the drive model covers: the low-current physics of a thyristor converter,
        pulse-level where it is about pulses; the analog regulators of the pulse-level one."""
        conv = self.converter
        if self.motor.brush_drop > 0.0 and conv.kind != "thyristor":
            raise ConfigError("motor.brush_drop", "is modelled with a thyristor converter "
                              "(current of one sign per bridge); set 0 for a pwm converter")
        if conv.model != "pulse":
            for name in ("latching_current", "holding_current", "gate_pulse_width"):
                if getattr(conv, name) > 0.0:
                    raise ConfigError(f"converter.{name}", "acts on the converter's pulses: "
                                      "it needs converter.model = 'pulse'")
            if self.regulators.implementation == "analog":
                raise ConfigError("regulators.implementation", "'analog' is modelled with "
                                  "the pulse-level thyristor converter (converter.model = "
                                  "'pulse')")

    @property
    def counts_per_metre(self) -> float:
        """Encoder counts per metre of table travel (counts/m)."""
        return self.encoder.counts_per_rev / (2.0 * math.pi * self.transmission.ratio)

    @property
    def volts_per_speed(self) -> float:
        """Speed reference that the drive turns into 1 m/s of table speed (V·s/m)."""
        return self.tacho.gain / self.transmission.ratio
