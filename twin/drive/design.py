"""Regulator design of one axis drive by the tuning rules of cascade (subordinate) control.

Every regulator constant of the drive is derived here from the motor, converter, tacho and
mechanics parameters of an :class:`~twin.config.AxisConfig`; nothing is typed in. The
controller side (the DCU derivation) and the documentation quote the resulting
:class:`DriveDesign`.

Structure (one axis)::

    U_ref ─ T1 ─(+)─ PI_ω ─ [±I_lim] ─(+)─ PI_i ─(+)─ converter ─(+)─ 1/R/(T_a·s+1) ─ i ─ k ─ τ
                 │(−)                 │(−)       │ E_est          │(−) E = k·ω
                 └─ K_C/(T_f·s+1) ─ ω └─── i     └─ (k/K_C)·U_tacho

Converter small time constant
    The regulators are sampled at the converter's firing instants, period T_p (the thyristor
    bridge: T_p = 1/(6·f_mains) = 3.33 ms at 50 Hz; PWM: T_p = 1/f_pwm), and the converter
    holds its mean output voltage constant between them. A zero-order hold delays on average
    by half its period, so **T_μ = T_p/2** (1.67 ms for the bridge) for the mean-value
    models. The pulse-level thyristor model (:mod:`twin.drive.pulse`) measures, as a real
    digital drive does, the *pulse-mean* current (the average over the last firing period:
    the instantaneous current carries the pulse ripple); that moving average delays by
    another T_p/2, so there **T_μ = T_p** (3.33 ms). An analog drive
    (``regulators.implementation = "analog"``) measures the current through a shunt and an
    RC filter T_fi (``regulators.current_filter``) and its firing unit takes the control
    voltage at the firing instants: **T_μ = T_p/2 + T_fi**, the textbook sum of the
    converter's dead time and the feedback filter. The converter gain is 1: the current
    regulator's output is the mean voltage itself (the arccos firing law makes the bridge
    linear in it in continuous conduction; the discontinuous-conduction compensation
    restores that gain below the boundary current).

Armature circuit
    The current loop is designed on the whole circuit a commissioning engineer measures:
    R_eff = R + n_d·r_T (the slope resistance r_T of the n_d thyristors in series: 2 for the
    bridge, 1 for the midpoint circuit) and L_eff = L + L_s + n·L_c (the smoothing reactor
    L_s and the commutating inductance L_c of the n phases in series with a conducting
    pair). The constant drops (brushes, thyristor thresholds) and the mains' deviation from
    its rating are the plant's alone: the design does not know them.

The machine's own settings
    The ``regulators`` section of the machine file holds what the drive on the machine is
    set to. Each of ``current_kp``, ``current_ti``, ``speed_kp`` and ``speed_ti`` that it
    gives replaces the derived value below (and only that one); the others stay derived.
    ``DriveDesign.regulator_overrides`` names the ones that came from the file.

Current loop: modulus optimum (MO, "technical optimum")
    Plant from mean voltage to current, the back-EMF being compensated (below):
    1/R · 1/(T_a·s + 1) · 1/(T_μ·s + 1), T_a = L/R. A PI regulator
    K_pi·(T_ii·s + 1)/(T_ii·s) cancels the large lag and sets the open loop to
    1/(2·T_μ·s·(T_μ·s + 1)):

        T_ii = T_a,        K_pi = R·T_a/(2·T_μ) = L/(2·T_μ)   (V/A)

    Closed loop 1/(2·T_μ²·s² + 2·T_μ·s + 1) (4.3 % overshoot), equivalent first-order lag
    **T_ie = 2·T_μ** for the outer loop.

Back-EMF compensation
    The motors here have T_m = J·R/k² comparable to T_a (8.3 ms vs 5 ms for the Tomsk rig), so
    the EMF is no slow disturbance: during an acceleration it ramps at k²·i/J (≈ 480 V/s at
    2 A) and an uncompensated PI would lag by a large fraction of the current. The current
    regulator therefore adds the EMF estimated from the tacho, E_est = (k/K_C)·U_tacho, to its
    output, which decouples the loop as the MO design assumes (switchable for studies).

Speed loop: symmetric optimum (SO) with spacing factor a
    Plant from current reference to the tacho signal: 1/(T_ie·s + 1) · k/(J·s) ·
    K_C/(T_f·s + 1), whose small lags are lumped into T_σ = T_ie + T_f = 2·T_μ + T_f. A PI
    regulator K_pω·(T_iω·s + 1)/(T_iω·s) with

        T_iω = a²·T_σ,     K_pω = J/(a·T_σ·K_C·k)   (A/V)

    puts the crossover at ω_c = 1/(a·T_σ), geometrically centred between 1/T_iω and 1/T_σ,
    with phase margin arctan(a) − arctan(1/a) (36.9° for a = 2). Its closed-loop zero at
    −1/T_iω causes ≈ 43 % overshoot to a reference step (a = 2); the reference filter
    **T1 = a²·T_σ** cancels that zero and leaves ≈ 8 % (the classic SO result), unless the
    machine file sets ``speed_loop.reference_filter``. Steady state: a reference of U volts
    gives ω = U/K_C.

Inertia
    J is the rotor inertia plus the moving mass reflected through the transmission,
    J = J_rotor + m·r² (r in m/rad). For the X axis of a cross table the moving mass is both
    carriages (``twin.config.moving_masses``); the load's elasticity and the friction are left to
    the regulators (rigid-body design, the standard practice).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from twin.config import AxisConfig
from twin.errors import ConfigError

__all__ = [
    "BRIDGE_THRESHOLD_FRACTION",
    "DriveDesign",
    "axis_inertia",
    "design",
]

BRIDGE_THRESHOLD_FRACTION = 2.5e-3
"""Current reference (fraction of the current limit) above which the bridge logic selects a
bridge; below it the logic keeps the present bridge (hysteresis against chattering)."""


@dataclass(frozen=True, kw_only=True)
class DriveDesign:
    """Derived constants of one axis drive (all SI). See the module docstring for the rules.

    Attributes
    ----------
    converter : str
        ``"thyristor"`` (non-circulating pair of bridges or midpoint circuits) or ``"pwm"``.
    model : str
        ``"pulse"`` (pulse-level thyristor converter) or ``"mean"`` (mean-value).
    pulse_number : int
        p: 6 (bridge) or 3 (midpoint circuit); PWM: 1.
    peak_voltage : float
        Û, peak of the voltage a conducting pair applies (V); PWM: the DC link.
    line_inductance : float
        L_c, commutating inductance per phase (H).
    series_phases : int
        Line inductances in series with a conducting pair (2 bridge, 1 midpoint).
    dcm_compensation : bool
        The pulse-level drive's current regulator adapts to discontinuous conduction.
    implementation : str
        ``"digital"`` (regulators sampled at the firing instants, pulse-mean current) or
        ``"analog"`` (continuous PI regulators, current through an RC filter).
    current_filter : float
        T_fi, the analog drive's filter on the measured current (s); 0 for a digital drive.
    sampling_period : float
        T_p, time between firing instants = regulator sampling period (s).
    converter_time_constant : float
        T_μ, equivalent lag of the sampled converter and current measurement (s): T_p/2,
        T_p for the pulse-level model (pulse-mean current), T_p/2 + T_fi for an analog
        drive.
    max_voltage : float
        U_d0 = 1.35·U_LL for the bridge, the DC link voltage for PWM (V).
    voltage_range : tuple of float
        (lowest, highest) mean voltage of the forward converter (V): U_d0·cos α_max and
        U_d0·cos α_min for the bridge (the reverse bridge mirrors it), ±U_dc for PWM.
    resistance : float
        Resistance the current loop sees, R_eff = R + n_d·r_T (Ω).
    inductance : float
        Inductance the current loop sees, L_eff = L + L_s + n·L_c (H).
    emf_constant : float
        k, back-EMF k·ω and torque k·i (V·s/rad = N·m/A).
    armature_time_constant : float
        T_a = L_eff/R (s).
    inertia : float
        J, total inertia at the motor shaft (kg·m²).
    mechanical_time_constant : float
        T_m = J·R/k² (s).
    current_kp : float
        Proportional gain of the current regulator (V/A): ``regulators.current_kp``, or
        K_pi = L_eff/(2·T_μ).
    current_ti : float
        Integral time of the current regulator (s): ``regulators.current_ti``, or T_ii = T_a.
    current_loop_time_constant : float
        T_ie = 2·T_μ, equivalent first-order lag of the closed current loop (s).
    current_limit : float
        Clamp of the current reference (A).
    emf_compensation : bool
        The current regulator adds the tacho-estimated EMF to its output.
    tacho_gain : float
        K_C (V·s/rad).
    tacho_filter : float
        T_f, tacho filter time constant (s).
    small_time_constant : float
        T_σ = 2·T_μ + T_f, lumped small lags of the speed loop (s).
    symmetric_optimum_a : float
        Spacing factor a of the symmetric optimum (1).
    speed_kp : float
        Proportional gain of the speed regulator (A/V): ``regulators.speed_kp``, or
        K_pω = J/(a·T_σ·K_C·k).
    speed_ti : float
        Integral time of the speed regulator (s): ``regulators.speed_ti``, or T_iω = a²·T_σ.
    reference_filter : float
        T1, reference filter time constant (s); 0 means no filter.
    bridge_threshold : float
        Current reference magnitude that makes the bridge logic select a bridge (A).
    regulator_overrides : tuple of str
        The regulator settings taken from the machine file's ``regulators`` section
        (``current_kp``, ``current_ti``, ``speed_kp``, ``speed_ti``); the rest are derived.
    """

    converter: str
    model: str
    pulse_number: int
    peak_voltage: float
    line_inductance: float
    series_phases: int
    dcm_compensation: bool
    sampling_period: float
    converter_time_constant: float
    max_voltage: float
    voltage_range: tuple[float, float]
    resistance: float
    inductance: float
    emf_constant: float
    armature_time_constant: float
    inertia: float
    mechanical_time_constant: float
    current_kp: float
    current_ti: float
    current_loop_time_constant: float
    current_limit: float
    emf_compensation: bool
    tacho_gain: float
    tacho_filter: float
    small_time_constant: float
    symmetric_optimum_a: float
    speed_kp: float
    speed_ti: float
    reference_filter: float
    bridge_threshold: float
    implementation: str = "digital"
    current_filter: float = 0.0
    regulator_overrides: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.converter not in ("thyristor", "pwm"):
            raise ConfigError("converter", f"must be 'thyristor' or 'pwm', got {self.converter!r}")
        lo, hi = self.voltage_range
        if not lo < hi:
            raise ConfigError("voltage_range", f"must be (lowest, highest), got {(lo, hi)}")
        if not 0.0 < hi <= self.max_voltage * (1.0 + 1e-12):
            raise ConfigError("voltage_range", f"highest voltage {hi} must lie in "
                              f"(0, max_voltage = {self.max_voltage}]")
        if self.implementation not in ("digital", "analog"):
            raise ConfigError("implementation", f"must be 'digital' or 'analog', got "
                              f"{self.implementation!r}")

    @property
    def current_regulator_designed(self) -> bool:
        """Both current-regulator settings are the modulus optimum's (none from the file)."""
        return not {"current_kp", "current_ti"} & set(self.regulator_overrides)

    @property
    def crossover(self) -> float:
        """Speed-loop crossover ω_c = 1/(a·T_σ) (rad/s)."""
        return 1.0 / (self.symmetric_optimum_a * self.small_time_constant)

    @property
    def phase_margin(self) -> float:
        """Speed-loop phase margin arctan(a) − arctan(1/a) of the SO design (rad)."""
        a = self.symmetric_optimum_a
        return math.atan(a) - math.atan(1.0 / a)

    @property
    def speed_gain(self) -> float:
        """Steady-state motor speed per volt of reference, 1/K_C (rad/(s·V))."""
        return 1.0 / self.tacho_gain


def axis_inertia(axis: AxisConfig, moving_mass: float | None = None) -> float:
    """Total inertia at the motor shaft J = J_rotor + m·r² (kg·m²).

    Parameters
    ----------
    axis : AxisConfig
        The axis.
    moving_mass : float, optional
        Mass moved by this axis (kg); default ``axis.mechanics.carriage_mass``.
    """
    m = axis.mechanics.carriage_mass if moving_mass is None else moving_mass
    if not (math.isfinite(m) and m >= 0.0):
        raise ConfigError("moving_mass", f"must be a finite mass >= 0 (kg), got {m}")
    r = axis.transmission.ratio
    return axis.mechanics.rotor_inertia + m * r * r


def design(axis: AxisConfig, *, moving_mass: float | None = None,
           emf_compensation: bool = True) -> DriveDesign:
    """Derive the drive's regulator constants from the axis parameters.

    Parameters
    ----------
    axis : AxisConfig
        Motor, converter, tacho, speed-loop settings and mechanics of the axis.
    moving_mass : float, optional
        Mass moved by the axis (kg), reflected into the inertia; default the axis' own
        carriage mass (``twin.config.moving_masses`` for the X axis of a cross table).
    emf_compensation : bool, optional
        Add the tacho-estimated back-EMF to the current regulator output (default True).

    Returns
    -------
    DriveDesign
        T_μ = T_p/2 (T_p pulse-level digital, T_p/2 + T_fi analog); current PI by the
        modulus optimum (K_pi = L_eff/(2·T_μ), T_ii = L_eff/R_eff); speed PI by the
        symmetric optimum (K_pω = J/(a·T_σ·K_C·k), T_iω = a²·T_σ, T_σ = 2·T_μ + T_f);
        T1 = a²·T_σ unless ``speed_loop.reference_filter`` is set; each of the four PI
        settings that the machine file's ``regulators`` section gives replaces its derived
        value.
    """
    motor, conv, tacho, loop = axis.motor, axis.converter, axis.tacho, axis.speed_loop
    reg = axis.regulators
    t_p = conv.firing_period
    pulse = conv.kind == "thyristor" and conv.model == "pulse"
    analog = reg.implementation == "analog"
    t_fi = reg.current_filter if analog else 0.0
    if analog:
        t_mu = 0.5 * t_p + t_fi
    else:
        t_mu = t_p if pulse else 0.5 * t_p
    u_max = conv.max_voltage
    if conv.kind == "thyristor":
        voltage_range = (u_max * math.cos(conv.max_firing_angle),
                         u_max * math.cos(conv.min_firing_angle))
        if voltage_range[1] <= 0.0:
            raise ConfigError("converter.min_firing_angle",
                              f"must be < 90° so that the bridge can rectify, got "
                              f"{math.degrees(conv.min_firing_angle):.1f}°")
    else:
        voltage_range = (-u_max, u_max)
    k = motor.emf_constant
    thyristor = conv.kind == "thyristor"
    series = conv.series_phases if thyristor else 0
    r_a = motor.armature_resistance + conv.series_devices * conv.thyristor_resistance
    l_a = (motor.armature_inductance + conv.smoothing_inductance
           + series * conv.line_inductance)
    t_a = l_a / r_a
    j = axis_inertia(axis, moving_mass)
    t_sigma = 2.0 * t_mu + tacho.filter_time_constant
    a = loop.symmetric_optimum_a
    t1 = a * a * t_sigma if loop.reference_filter is None else loop.reference_filter
    derived = {"current_kp": l_a / (2.0 * t_mu), "current_ti": t_a,
               "speed_kp": j / (a * t_sigma * tacho.gain * k), "speed_ti": a * a * t_sigma}
    overrides = tuple(name for name in derived if getattr(reg, name) is not None)
    settings = {name: getattr(reg, name) if name in overrides else value
                for name, value in derived.items()}
    return DriveDesign(
        converter=conv.kind,
        model=conv.model if thyristor else "mean",
        pulse_number=conv.pulse_number if thyristor else 1,
        peak_voltage=conv.peak_voltage,
        line_inductance=conv.line_inductance if thyristor else 0.0,
        series_phases=series,
        dcm_compensation=bool(thyristor and pulse and conv.dcm_compensation),
        sampling_period=t_p,
        converter_time_constant=t_mu,
        max_voltage=u_max,
        voltage_range=voltage_range,
        resistance=r_a,
        inductance=l_a,
        emf_constant=k,
        armature_time_constant=t_a,
        inertia=j,
        mechanical_time_constant=j * r_a / (k * k),
        current_kp=settings["current_kp"],
        current_ti=settings["current_ti"],
        current_loop_time_constant=2.0 * t_mu,
        current_limit=motor.current_limit,
        emf_compensation=bool(emf_compensation),
        tacho_gain=tacho.gain,
        tacho_filter=tacho.filter_time_constant,
        small_time_constant=t_sigma,
        symmetric_optimum_a=a,
        speed_kp=settings["speed_kp"],
        speed_ti=settings["speed_ti"],
        reference_filter=t1,
        bridge_threshold=BRIDGE_THRESHOLD_FRACTION * motor.current_limit,
        implementation=reg.implementation,
        current_filter=t_fi,
        regulator_overrides=overrides,
    )
