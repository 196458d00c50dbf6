"""The axis drives as one object: the plant's interface to the converter/motor/loop model.

:class:`Drives` holds the state of all axes in flat float64 arrays and advances them with one
compiled call (:func:`twin.drive.kernel.drive_step`) per update interval. What each update
models, per axis:

- reference filter T1 on the speed reference (V), which the plant has already quantised and
  saturated like the DAC does;
- tachogenerator K_C·ω through its filter T_f (plus optional noise on the sampled signal);
- at each firing instant t_j = j·T_p (the same grid for every axis, phase 0 at time 0): the
  PI speed regulator (symmetric optimum) with the current limit, the bridge logic, the PI
  current regulator (modulus optimum, back-EMF compensation) and the firing angle;
- converter: a non-circulating pair of thyristor converters, simulated at pulse level
  (``converter.model = "pulse"``, :mod:`twin.drive.pulse`: the instantaneous voltage of the
  conducting pair, firing synchronised to the mains, discontinuous conduction wherever the
  circuit gives it, commutation overlap through the line inductance) or by its mean voltage
  (``"mean"``: U_d0·cos α held between firing instants, the 300 Hz ripple left out, so
  current stops only where the mean voltage falls below the EMF); or a PWM bridge (averaged
  voltage held over each PWM period, clamped at ±U_dc, current of either sign). The logic
  switching unit selects a bridge when the current reference exceeds
  ``DriveDesign.bridge_threshold`` in its sense, reverses only at zero current, removes the
  pulses and releases the other bridge after ``converter.reversal_pause``; a bridge starts
  at the EMF balance;
- armature L·di/dt = u − k·ω − R·i solved exactly, with ω(t) extrapolated linearly inside
  the interval from the last two speeds the plant passed; the returned torque is k times the
  interval-average current.

Enable and faults
    ``enable(False)`` (and a fault) block the converter at the next firing instant: the
    regulators and the reference filter are reset, a flowing current is forced to zero
    (bridge at the inverter end stop α_max; PWM freewheels against the DC link) and the
    pulses are then removed. A fault trips when the current reference stays at the current
    limit for longer than ``overload_time`` (a stalled or overloaded axis: the drive's
    overload protection). It latches until ``enable(False)`` or ``reset()``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from twin.config import AXES, AxisConfig, MachineConfig
from twin.drive import kernel as K
from twin.drive import layout as L
from twin.drive.dcm import N_ALPHA, N_EMF, build_table
from twin.drive.design import DriveDesign, design
from twin.errors import ConfigError, SimulationError

__all__ = ["Drives"]

_INPUT_NAMES = {K.STATUS_NONFINITE_UREF: "speed reference u_ref",
                K.STATUS_NONFINITE_OMEGA: "rotor speed omega",
                K.STATUS_NONFINITE_RESULT: "drive state (result)"}


DCM_INTEGRAL_GAIN = 0.5
"""Per-pulse integral gain g of the current regulator in discontinuous conduction: the
residual current error falls by (1 − g) per pulse on the linearised plant (design rule in
``models/README.md``)."""


def _params(d: DriveDesign, axis: AxisConfig, overload_time: float,
            extrapolate: bool) -> np.ndarray:
    p = np.zeros(L.NP)
    p[L.P_R] = d.resistance
    p[L.P_TA] = d.armature_time_constant
    p[L.P_K] = d.emf_constant
    p[L.P_KC] = d.tacho_gain
    p[L.P_TF] = d.tacho_filter
    p[L.P_T1] = d.reference_filter
    p[L.P_KPS] = d.speed_kp
    p[L.P_TIS] = d.speed_ti
    p[L.P_KPC] = d.current_kp
    p[L.P_TIC] = d.current_ti
    p[L.P_ILIM] = d.current_limit
    p[L.P_TP] = d.sampling_period
    p[L.P_UMAX] = d.max_voltage
    p[L.P_VLO], p[L.P_VHI] = d.voltage_range
    p[L.P_PWM] = 1.0 if d.converter == "pwm" else 0.0
    p[L.P_PAUSE] = axis.converter.reversal_pause
    p[L.P_ITH] = d.bridge_threshold
    p[L.P_EMFC] = 1.0 if d.emf_compensation else 0.0
    p[L.P_NOISE] = axis.tacho.noise
    p[L.P_OVERLOAD] = overload_time
    p[L.P_EXTRAP] = 1.0 if extrapolate else 0.0
    p[L.P_MODEL] = 1.0 if d.model == "pulse" else 0.0
    p[L.P_UHAT] = d.peak_voltage
    p[L.P_WM] = 2.0 * math.pi * axis.converter.mains_frequency
    p[L.P_PN] = d.pulse_number
    conv, motor = axis.converter, axis.motor
    p[L.P_L] = motor.armature_inductance + conv.smoothing_inductance
    p[L.P_LC] = d.line_inductance
    p[L.P_NSER] = d.series_phases
    p[L.P_DCMC] = 1.0 if d.dcm_compensation else 0.0
    p[L.P_AMIN] = axis.converter.min_firing_angle
    p[L.P_AMAX] = axis.converter.max_firing_angle
    p[L.P_ALPHA_FIX] = math.nan
    p[L.P_DCMG] = DCM_INTEGRAL_GAIN
    if d.converter == "thyristor":
        t_p = d.sampling_period
        p[L.P_T0] = (axis.converter.mains_phase / (2.0 * math.pi * axis.converter.mains_frequency)
                     ) % t_p
    # the plant's own: the mains as it is, the drops, the thyristors' currents
    p[L.P_UREAL] = d.peak_voltage * (1.0 + conv.mains_deviation)
    p[L.P_MAINS] = 1.0 + conv.mains_deviation if d.converter == "thyristor" else 1.0
    p[L.P_UDROP] = motor.brush_drop + conv.series_devices * conv.thyristor_threshold
    p[L.P_RT] = conv.thyristor_resistance
    p[L.P_IH] = conv.holding_current
    p[L.P_IL] = conv.latching_current
    p[L.P_TG] = conv.gate_pulse_width
    p[L.P_RM] = motor.armature_resistance
    p[L.P_LM] = motor.armature_inductance
    p[L.P_UB] = motor.brush_drop
    p[L.P_ANALOG] = 1.0 if d.implementation == "analog" else 0.0
    p[L.P_TFI] = d.current_filter
    for k, (harmonic, percent) in enumerate(axis.tacho.ripple):
        p[L.P_RIPPLE + 2 * k] = harmonic
        p[L.P_RIPPLE + 2 * k + 1] = 0.01 * percent
    return p


def _dcm_table(d: DriveDesign) -> np.ndarray:
    """The discontinuous characteristic a pulse-level drive's firing unit inverts."""
    if not d.dcm_compensation:
        return np.zeros((N_EMF, N_ALPHA))
    w = 2.0 * math.pi / (d.pulse_number * d.sampling_period)
    return build_table(float(d.pulse_number), w * d.armature_time_constant)


class Drives:
    """All axis drives of a machine, advanced together every ``dt``.

    Parameters
    ----------
    axes : sequence of AxisConfig
        One entry per axis (the plant passes x, y).
    dt : float
        Update interval (s); the plant calls :meth:`step` every ``dt``.
    rng : numpy.random.Generator, optional
        Source of the tacho noise (``tacho.noise`` > 0); default ``default_rng(0)``. Noise
        draws happen only when some axis has noise, so runs stay deterministic.
    moving_masses : sequence of float, optional
        Mass moved by each axis (kg) for the speed-loop design; default each axis' own
        carriage mass. :meth:`from_machine` passes the cross-table masses.
    emf_compensation : bool, optional
        Back-EMF compensation in the current regulators (default True).
    overload_time : float, optional
        Time at the current limit that trips the fault (s), default 1.0.
    extrapolate_speed : bool, optional
        Inside an interval take ω(t) linear, extrapolated from the last two ``omega``
        inputs (default True, second-order coupling); False holds ω at its start value.
    names : sequence of str, optional
        Axis names for messages; default ``("x", "y")`` for two axes, else indices.
    firing_log : int, optional
        Keep the first ``firing_log`` firings of each axis (pulse-level model):
        :meth:`firings`. Default 0.
    sub_steps : int, optional
        Sub-steps of each interval over which the torque is also averaged
        (:attr:`sub_torque`: the plant's physics steps). Default 1.

    Raises
    ------
    ConfigError
        If ``dt``, ``overload_time`` or the axis parameters are invalid.

    Examples
    --------
    >>> drives = Drives([cfg.axes["x"], cfg.axes["y"]], dt=1e-3)   # doctest: +SKIP
    >>> tau = drives.step(np.array([1.0, 0.0]), omega)               # doctest: +SKIP
    """

    def __init__(self, axes: Sequence[AxisConfig], dt: float, *,
                 rng: np.random.Generator | None = None,
                 moving_masses: Sequence[float] | None = None,
                 emf_compensation: bool = True, overload_time: float = 1.0,
                 extrapolate_speed: bool = True, names: Sequence[str] | None = None,
                 firing_log: int = 0, sub_steps: int = 1):
        axes = list(axes)
        if not axes:
            raise ConfigError("axes", "need at least one axis")
        if not (isinstance(dt, int | float) and math.isfinite(dt) and dt > 0.0):
            raise ConfigError("dt", f"must be a finite interval > 0 (s), got {dt!r}")
        if not (math.isfinite(overload_time) and overload_time > 0.0):
            raise ConfigError("overload_time", f"must be > 0 (s), got {overload_time!r}")
        n = len(axes)
        masses = [None] * n if moving_masses is None else list(moving_masses)
        if len(masses) != n:
            raise ConfigError("moving_masses", f"needs {n} entries, got {len(masses)}")
        if names is None:
            names = AXES if n == len(AXES) else tuple(str(k) for k in range(n))
        if len(names) != n:
            raise ConfigError("names", f"needs {n} entries, got {len(names)}")
        self.names: tuple[str, ...] = tuple(names)
        self.designs: tuple[DriveDesign, ...] = tuple(
            design(ax, moving_mass=m, emf_compensation=emf_compensation)
            for ax, m in zip(axes, masses, strict=True))
        self.dt = float(dt)
        self._params = np.ascontiguousarray(
            [_params(d, ax, overload_time, extrapolate_speed)
             for d, ax in zip(self.designs, axes, strict=True)])
        self._tables = np.ascontiguousarray([_dcm_table(d) for d in self.designs])
        self._noisy = bool(np.any(self._params[:, L.P_NOISE] > 0.0))
        self._rng = rng if rng is not None else np.random.default_rng(0)
        firings = math.ceil(self.dt / float(np.min(self._params[:, L.P_TP]))) + 3
        self._noise = np.zeros((n, firings))
        self._log = np.zeros((n, max(int(firing_log), 0), L.NLOG))
        self._theta = np.zeros(n)
        if not (isinstance(sub_steps, int) and sub_steps >= 1):
            raise ConfigError("sub_steps", f"must be an integer >= 1, got {sub_steps!r}")
        self._sub = np.zeros((n, sub_steps))
        self._scratch = np.zeros(12)
        self._state = L.empty_state(n)
        self._n_step = 0
        self._enabled = True
        self.reset()

    @classmethod
    def from_machine(cls, machine: MachineConfig, *, dt: float | None = None,
                     **options) -> Drives:
        """Drives of both axes of ``machine``; the X axis carries the Y carriage.

        ``dt`` defaults to ``simulation.timestep · simulation.drive_substeps``; further
        keyword options go to the constructor.
        """
        if dt is None:
            dt = machine.simulation.timestep * machine.simulation.drive_substeps
        masses = machine.moving_masses()
        options.setdefault("sub_steps", machine.simulation.drive_substeps)
        return cls([machine.axes[a] for a in AXES], dt,
                   moving_masses=[masses[a] for a in AXES], **options)

    # ------------------------------------------------------------------ cyclic use
    def reset(self) -> None:
        """Zero state at time 0: no current, blocked bridges, enabled, faults cleared."""
        self._state[:] = L.empty_state(len(self.designs))
        self._log[:] = 0.0
        self._n_step = 0
        self._enabled = True

    def enable(self, flag: bool) -> None:
        """Drive enable input. ``False`` blocks the converters (and acknowledges faults)."""
        self._enabled = bool(flag)
        if not self._enabled:
            self._state[:, L.S_FAULT] = 0.0

    def step(self, u_ref: np.ndarray, omega: np.ndarray,
             theta: np.ndarray | None = None) -> np.ndarray:
        """Advance all drives by ``dt``.

        Parameters
        ----------
        u_ref : ndarray, shape (n,)
            Speed references at the drive inputs (V), already quantised and saturated.
        omega : ndarray, shape (n,)
            Rotor speeds at the start of the interval (rad/s).
        theta : ndarray, shape (n,), optional
            Rotor angles at the start of the interval (rad), for the tacho ripple; default
            the last given (0 at first).

        Returns
        -------
        ndarray, shape (n,)
            Average motor torque over the interval (N·m).

        Raises
        ------
        SimulationError
            If an input is not finite (naming the input and the axis); nothing changes then.
        """
        u = np.ascontiguousarray(u_ref, dtype=np.float64)
        w = np.ascontiguousarray(omega, dtype=np.float64)
        n = len(self.designs)
        if u.shape != (n,) or w.shape != (n,):
            raise ValueError(f"u_ref and omega must have shape ({n},), got {u.shape} and "
                             f"{w.shape}")
        if theta is not None:
            self._theta[:] = theta
        if self._noisy:
            self._noise[:] = self._rng.standard_normal(self._noise.shape)
        tau = np.empty(n)
        status = K.drive_step(self._params, self._state, self._tables, u, w, self._theta,
                              self._noise, self._log, self._n_step, self.dt, self._enabled,
                              tau, self._sub, self._scratch)
        if status:
            code, axis = divmod(status, 1000)
            value = {K.STATUS_NONFINITE_UREF: u, K.STATUS_NONFINITE_OMEGA: w}.get(code)
            got = f" = {value[axis]}" if value is not None else ""
            raise SimulationError(f"drive {self.names[axis]}: {_INPUT_NAMES[code]} is not "
                                  f"finite{got} at t = {self.time:.6f} s")
        self._n_step += 1
        return tau

    def step_into(self, u_ref: np.ndarray, omega: np.ndarray, torque: np.ndarray,
                  theta: np.ndarray) -> None:
        """``step`` for the plant's hot loop: no copies, the torque written into ``torque``.

        The caller guarantees float64 arrays of shape (n,) (``torque`` may be a view of the
        simulator's applied forces, ``theta`` of its rotor angles); non-finite inputs still
        raise ``SimulationError``.
        """
        if self._noisy:
            self._noise[:] = self._rng.standard_normal(self._noise.shape)
        status = K.drive_step(self._params, self._state, self._tables, u_ref, omega, theta,
                              self._noise, self._log, self._n_step, self.dt, self._enabled,
                              torque, self._sub, self._scratch)
        if status:
            self.step(u_ref, omega, theta)  # the checked path raises the named error
        self._n_step += 1

    def kernel_arrays(self) -> tuple[np.ndarray, ...]:
        """(params, state, tables, noise, log, sub_torque, scratch): the live arrays
        ``kernel.drive_step`` works on, for a caller that runs the kernel itself in a
        compiled loop (``twin.plant.loop``). Such a caller must count the intervals it ran
        with :meth:`advance`."""
        return (self._params, self._state, self._tables, self._noise, self._log, self._sub,
                self._scratch)

    @property
    def sub_torque(self) -> np.ndarray:
        """Average torque over each sub-step of the last interval (N·m), shape (n, m): a
        view, valid until the next step."""
        return self._sub

    def firings(self) -> list[np.ndarray]:
        """The firing log of each axis (pulse-level model; ``firing_log`` entries at most):
        arrays of shape (k, 4) with time (s), pair index, bridge (±1, or 0 where the gate
        pulses were removed) and firing angle (rad)."""
        counts = self._state[:, L.S_NLOG].astype(int)
        return [self._log[a, :counts[a]].copy() for a in range(len(self.designs))]

    def set_firing_angle(self, alpha: Sequence[float] | None) -> None:
        """Open-loop converter: fire the forward thyristor converter of each axis at this
        angle (rad) instead of regulating (pulse-level model; tests and diagnostics).
        ``None`` returns to regulation."""
        values = [math.nan] * len(self.designs) if alpha is None else list(alpha)
        if len(values) != len(self.designs):
            raise ValueError(f"alpha needs {len(self.designs)} entries, got {len(values)}")
        self._params[:, L.P_ALPHA_FIX] = values

    def advance(self, intervals: int) -> None:
        """Count ``intervals`` updates run outside :meth:`step` (by the compiled loop)."""
        self._n_step += intervals

    @property
    def n_step(self) -> int:
        """Updates so far (the next one starts at ``n_step · dt``)."""
        return self._n_step

    @property
    def noisy(self) -> bool:
        """Tacho noise is on (needs the random generator between kernel calls)."""
        return self._noisy

    # ------------------------------------------------------------------ readouts
    def snapshot(self) -> list[list[float]]:
        """The whole state as nested lists (axis, column ``kernel.S_*``): one cheap copy for
        a caller that needs several readouts per period."""
        return self._state.tolist()

    def _column(self, col: int) -> np.ndarray:
        return self._state[:, col].copy()

    @property
    def time(self) -> float:
        """Time of the drives (s): number of updates · dt."""
        return self._n_step * self.dt

    @property
    def enabled(self) -> bool:
        """The enable input."""
        return self._enabled

    @property
    def tacho_volts(self) -> np.ndarray:
        """Filtered tacho output as the ADC reads it (V), shape (n,)."""
        return self._column(L.S_ADC)

    @property
    def current(self) -> np.ndarray:
        """Armature current at the end of the last interval (A), shape (n,)."""
        return self._column(L.S_I)

    @property
    def current_reference(self) -> np.ndarray:
        """Speed-regulator output = current reference (A), shape (n,)."""
        return self._column(L.S_IREF)

    @property
    def voltage(self) -> np.ndarray:
        """Converter mean output voltage commanded now (V), shape (n,); 0 when blocked: the
        mean value model's voltage, and b·U_d0·cos α of the last firing for the pulse-level
        one (the mean voltage it would give in continuous conduction)."""
        return self._column(L.S_V)

    @property
    def torque(self) -> np.ndarray:
        """Average motor torque over the last interval (N·m), shape (n,)."""
        return self._column(L.S_TORQUE)

    @property
    def firing_angle(self) -> np.ndarray:
        """Firing angle α (rad), shape (n,); NaN for PWM and while the pulses are removed."""
        return self._column(L.S_ALPHA)

    @property
    def bridge(self) -> np.ndarray:
        """Active converter, shape (n,), int: +1 forward, −1 reverse, 0 blocked or pause.

        A PWM converter reports +1 while enabled (one four-quadrant bridge).
        """
        return self._state[:, L.S_BRIDGE].astype(np.int64)

    @property
    def speed_reference(self) -> np.ndarray:
        """Speed reference after the T1 filter (V), shape (n,)."""
        return self._column(L.S_REF)

    @property
    def output_voltage(self) -> np.ndarray:
        """Mean motor terminal voltage over the last interval (V), shape (n,): what the
        converter really applied (R·i + L·di/dt + E averaged; the EMF while no current
        flows). In discontinuous conduction it differs from the commanded
        :attr:`voltage`, which is U_d0·cos α."""
        return self._column(L.S_VOUT)

    @property
    def conduction(self) -> np.ndarray:
        """Fraction of the last interval during which armature current flowed, (n,)."""
        return self._column(L.S_CONDUCT)

    @property
    def measured_current(self) -> np.ndarray:
        """The current the current regulator last measured (A), (n,): the pulse mean for the
        pulse-level model."""
        return self._column(L.S_IMEAS)

    @property
    def fault(self) -> np.ndarray:
        """Latched overload trip (current reference at its limit > overload_time), (n,)."""
        return self._state[:, L.S_FAULT] != 0.0
