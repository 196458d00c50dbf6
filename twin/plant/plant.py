"""The physical twin: the MuJoCo cross table driven by the two axis drives.

:class:`Plant` advances the drives (``twin.drive``) and the mechanics (``twin.plant.model``) in
lock-step: every drive update interval ``dt_drive = simulation.timestep ·
simulation.drive_substeps`` the drives turn the quantised speed references and the rotor
speeds into an interval-average motor torque, which MuJoCo then applies to the rotor hinges
(``qfrc_applied``) for ``drive_substeps`` physics steps. :meth:`Plant.read` gives what real
I/O hardware gives (encoder counters, tacho voltages, debounced switches);
:meth:`Plant.truth` what only a twin knows.

Typical use::

    plant = Plant.from_machine("tomsk_xy")
    plant.reset()                                   # keyframe "home", drives enabled
    status = plant.step(np.array([1.0, 0.0]), 5e-3)  # 1 V on X for one 5 ms period
    counts = plant.read().encoder_counts

Sensors and switches
    Encoders sit on the motor shafts: ``counts = floor(θ·cpr/2π) + offset`` wrapped to the
    counter width (``encoder.bits``); at reset the offset is 0 (counts are then the table
    position in counts while the screw is relaxed) or set so the counter reads a preset.
    The switches are sampled at the end of every drive interval and debounced over
    ``switches.debounce``: a raw change must persist that long before the output follows.
    ``limit_min`` is closed for x ≤ limit_min, ``limit_max`` for x ≥ limit_max and ``home``
    for |x − home| ≤ home_width/2.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

from twin.config import AXES, MachineConfig
from twin.controller.io import Inputs
from twin.drive import Drives
from twin.errors import ConfigError, SimulationError
from twin.plant import loop as plant_loop
from twin.plant.accelerometer import Accelerometer
from twin.plant.model import (
    chain_parameters,
    load_model,
    passive_parameters,
    resolve_machine,
)
from twin.plant.records import (
    FINE_FIELDS,
    FINE_WIDTH,
    FLAGS,
    TRUTH_FIELDS,
    AxisMonitor,
    StepStatus,
    Truth,
)

__all__ = ["FINE_FIELDS", "FINE_WIDTH", "TRUTH_FIELDS", "Plant", "StepStatus",
           "Truth"]

_BAD_STATE = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")
FINE_RING = 1 << 16
"""Rows of the plant's ring buffer of drive-rate samples (65 s of tomsk_xy, 16 s of
laser_belt; 5.8 MB)."""
_WARNING_NAMES = tuple(mujoco.mjtWarning(i).name for i in range(mujoco.mjtWarning.mjNWARNING))


class Plant:
    """The cross table with its drives (see the module docstring).

    Parameters
    ----------
    config : MachineConfig
        The machine.
    noise : bool
        Sensor noise as the machine file gives it (``encoder.noise_counts``,
        ``tacho.noise``); on by default, seeded, so a run is still reproducible. False
        silences it (the presets have none).
    seed : int, optional
        Seed of the noise generator; default ``simulation.seed``.

    Attributes
    ----------
    config : MachineConfig
    model : mujoco.MjModel
    data : mujoco.MjData
    drives : twin.drive.Drives
    drive_dt : float
        Drive update interval (s): ``simulation.timestep · simulation.drive_substeps``;
        :meth:`step` durations are multiples of it.
    """

    def __init__(self, config: MachineConfig, *, noise: bool = True, seed: int | None = None):
        self.config = config
        self.noise = bool(noise)
        self._rng = np.random.default_rng(config.simulation.seed if seed is None else seed)
        if not self.noise:  # the drives model the tacho noise: silence it at the source
            config = config.with_overrides({"axes.*.tacho.noise": 0.0})
        self.model = load_model(config)
        self.data = mujoco.MjData(self.model)
        self.drive_dt = config.simulation.timestep * config.simulation.drive_substeps
        self.drives = Drives.from_machine(config, dt=self.drive_dt, rng=self._rng)
        self._substeps = config.simulation.drive_substeps
        self._key_ids = {self.model.key(i).name: i for i in range(self.model.nkey)}

        m, d = self.model, self.data
        table = _pair_slices(m, AXES)
        rotor = _pair_slices(m, [f"{a}_rotor" for a in AXES])
        self._table_pos, self._table_vel = d.qpos[table[0]], d.qvel[table[1]]
        self._rotor_pos, self._rotor_vel = d.qpos[rotor[0]], d.qvel[rotor[1]]
        self._torque = d.qfrc_applied[rotor[1]]
        self._slide_force = d.qfrc_applied[table[1]]
        self._slide_joints = [m.joint(a).id for a in AXES]
        self._table_body = int(m.body("y_carriage").id)
        self._warning_count = d.warning.number  # a live view of the counters

        axes = [config.axes[a] for a in AXES]
        self._ratio = np.array([ax.transmission.ratio for ax in axes])
        self._dac = np.array([(2.0 * ax.dac.full_scale / 2**ax.dac.bits,
                               -(2 ** (ax.dac.bits - 1)), 2 ** (ax.dac.bits - 1) - 1,
                               1.0 + ax.dac.gain_error, ax.dac.offset)
                              for ax in axes])  # (LSB (V), code range, gain, offset (V))
        self._cpr = tuple(ax.encoder.counts_per_rev / (2.0 * math.pi) for ax in axes)
        """Encoder counts per rotor radian, per axis."""
        # two's complement masks: -1 & (2³² − 1) = 2³² − 1; a 64-bit counter stays signed
        self._mask = tuple((1 << ax.encoder.bits) - 1 if ax.encoder.bits < 64 else -1
                           for ax in axes)
        self._offset = [0, 0]
        """Counts added to each counter (an encoder preset), Python ints: the one copy."""
        self._encoder_noise = np.array([ax.encoder.noise_counts for ax in axes])
        self._noisy_counts = bool(self.noise and self._encoder_noise.any())
        """The counters are read with noise (the tacho's is drawn by the drives)."""
        self._travel = [ax.mechanics.travel for ax in axes]
        self._monitors = [AxisMonitor(ax.switches, ax.mechanics.travel) for ax in axes]
        self._intervals: dict[float, int] = {}
        self._samples = np.empty((0, FINE_WIDTH))
        self._fine = self._samples
        self._ring = np.full((FINE_RING, FINE_WIDTH), np.nan)
        self._ring_n = 0      # rows ever written to the ring
        self._ring_read = 0   # rows drained
        self._passive = passive_parameters(config)
        self._has_passive = bool(np.any(self._passive))
        self._chain = chain_parameters(config, self.model)
        self._has_chain = bool(self._chain[:, 0].any())
        """An axial spring varies with the nut: written before every physics step."""
        self._mj_arrays = (d.qpos, d.qvel, d.qfrc_applied, m.tendon_stiffness,
                           m.tendon_damping)
        shafts = self._chain[:, 12].astype(np.int64)
        self._spring_adr = np.where(shafts >= 0, shafts, m.jnt_qposadr[[m.joint(
            f"{a}_rotor").id for a in AXES]]).astype(np.int64)
        self._spring_ratio = np.array([ax.transmission.screw_ratio if s >= 0 else r
                                       for ax, s, r in zip(axes, shafts.tolist(),
                                                           self._ratio.tolist(), strict=True)])
        """Where the axial (screw) spring's driver sits in qpos (the rotor, or the screw
        body), and its ratio (m/rad): the screw deflection is ratio·qpos − x."""
        self._drive_torque = np.zeros(2)  # the drives' interval-average torque
        self._noise_block = np.zeros((1, *self.drives.kernel_arrays()[3].shape))
        self._spring_f = (*self._spring_ratio.tolist(), *self._spring_adr.tolist())
        """The axial springs' ratios and qpos addresses as Python numbers, for rows."""
        self._out = np.zeros(plant_loop.NREADOUT)
        self._ro: list[float] = [0.0] * plant_loop.NREADOUT
        """The drive state this period's readers need (``plant_loop.readout``), as floats."""
        self._compiled = plant_loop.available()
        """Run drive intervals in the compiled loop (``twin.plant.loop``)."""
        if self._compiled:
            self._addresses = plant_loop.addresses(self.model, self.data)
        self._extent = np.zeros(4)  # lowest and highest table sample of each axis in a step
        self.accelerometer = (Accelerometer(config.accelerometer, noise=self.noise)
                              if config.accelerometer.mounted else None)
        """The table accelerometer (``twin.plant.accelerometer``), or None: not mounted."""
        self._no_steps = np.empty((0, 2))
        self._steps = self._no_steps
        """The table velocity after each physics step of a step (the accelerometer's)."""
        self._u = np.zeros(2)
        self.reset()
        if self._compiled:
            self._warm_up()

    def _warm_up(self) -> None:
        """Compile the drive loop now, not in a run's first period: it calls MuJoCo through
        a C pointer, so numba cannot cache it, and compiling takes 0.6 s (seconds on a
        loaded machine): a paced loop would miss its deadlines, and a stop signal would
        land inside LLVM. The call is the real one with no interval (``n = 0``), so the
        types match and nothing moves; it only quantises a zero request into ``u``, which
        every step writes anew."""
        params, state, tables, _, log, sub, scratch = self.drives.kernel_arrays()
        plant_loop.step_intervals(
            *self._addresses, 0, self._substeps, params, state, tables, np.zeros(2), self._dac,
            self._u, self._noise_block, log, self.drives.n_step, self.drives.dt,
            self.drives.enabled, self._passive, self._has_passive, self._chain,
            self._has_chain, self._drive_torque, sub, scratch, self._torque,
            self._slide_force, self._table_pos, self._table_vel, self._rotor_pos,
            self._rotor_vel, *self._mj_arrays, self._spring_adr, self._spring_ratio,
            self._samples[:0], self._no_steps, self._extent, self._ring, self._ring_n,
            self._out)
        self._u[:] = 0.0

    @classmethod
    def from_machine(cls, machine: str | Path | MachineConfig, *, noise: bool = True,
                     seed: int | None = None) -> Plant:
        """A plant of a preset name, a machine TOML path or a config."""
        return cls(resolve_machine(machine), noise=noise, seed=seed)

    # ------------------------------------------------------------------ control
    @property
    def time(self) -> float:
        """Plant time (s)."""
        return float(self.data.time)

    def reset(self, keyframe: str = "home", *, positions: np.ndarray | None = None,
              encoder_preset: np.ndarray | None = None, seed: int | None = None) -> None:
        """Back to rest at time 0: mechanics at a keyframe, drives reset and enabled.

        Parameters
        ----------
        keyframe : str
            Model keyframe ("home": tables at the home switches, screws relaxed).
        positions : ndarray, shape (2,), optional
            Table positions instead (m), within the travel; rotors at positions/r.
        encoder_preset : ndarray, shape (2,), optional
            Counter values to preload (counts); default: offset 0.
        seed : int, optional
            Reseed the noise generator (default: keep its stream).

        Raises
        ------
        ValueError
            Unknown keyframe, or positions of the wrong shape or outside the travel.
        """
        m, d = self.model, self.data
        if keyframe not in self._key_ids:
            raise ValueError(f"keyframe must be one of {sorted(self._key_ids)}, got {keyframe!r}")
        mujoco.mj_resetDataKeyframe(m, d, self._key_ids[keyframe])
        if positions is not None:
            x = np.asarray(positions, dtype=float)
            if x.shape != (2,) or not all(lo <= xi <= hi for xi, (lo, hi)
                                          in zip(x.tolist(), self._travel, strict=True)):
                travel = ", ".join(f"{a} {lo * 1e3:g} … {hi * 1e3:g} mm" for a, (lo, hi)
                                   in zip("XY", self._travel, strict=True))
                got = ", ".join(f"{v * 1e3:g}" for v in x.ravel().tolist())
                raise ConfigError("start", f"must be 2 positions within the travel ({travel}), "
                                  f"got {got} mm")
            self._table_pos[:] = x
            self._rotor_pos[:] = x / self._ratio
            for k, axis in enumerate(AXES):  # the screw bodies, springs relaxed
                shaft = int(self._chain[k, 12])
                if shaft >= 0:
                    d.qpos[shaft] = x[k] / self.config.axes[axis].transmission.screw_ratio
            d.qvel[:] = 0.0
        if self._has_chain:
            plant_loop.chain_springs(self._chain, self._table_pos, *self._mj_arrays[3:],
                                     self._passive)
        mujoco.mj_forward(m, d)
        if seed is not None:
            self._rng.bit_generator.state = np.random.default_rng(seed).bit_generator.state
        self.drives.reset()
        plant_loop.readout(self.drives.kernel_arrays()[1], self._out)
        self._ro = self._out.tolist()
        self._ring_read = self._ring_n  # samples from before the reset are not drained
        if self.accelerometer is not None:
            self.accelerometer.reset(d.time, self._table_vel)
        self._offset = [0, 0]
        if encoder_preset is not None:
            self._offset = [int(p) - c for p, c in zip(np.asarray(encoder_preset, np.int64)
                                                       .tolist(), self._raw_counts(),
                                                       strict=True)]
        self._warnings_seen = self._warning_count.tobytes()
        for sw, x in zip(self._monitors, self._table_pos.tolist(), strict=True):
            sw.settle(x)

    def enable(self, flag: bool) -> None:
        """Drive enable; ``False`` blocks both converters (and acknowledges a fault, which
        the next sample shows)."""
        self.drives.enable(flag)
        plant_loop.readout(self.drives.kernel_arrays()[1], self._out)
        self._ro = self._out.tolist()

    def set_table_force(self, force: np.ndarray) -> None:
        """Push on the table (the Y carriage, where the accelerometer sits) with ``force``
        (N, shape (2,): along the X and the Y slide), held by every physics step until
        changed; a reset clears it. A modal hammer's blow (``twin.session.hammer``): an
        outside force on the body, not one of the machine's own."""
        f = np.asarray(force, dtype=float)
        if f.shape != (2,) or not np.all(np.isfinite(f)):
            raise ValueError(f"force must be 2 finite values (N), got {force!r}")
        d = self.data
        d.xfrc_applied[self._table_body, :3] = (f[0] * d.xaxis[self._slide_joints[0]]
                                                + f[1] * d.xaxis[self._slide_joints[1]])

    def step(self, dac_volts: np.ndarray, duration: float) -> StepStatus:
        """Apply DAC voltages for ``duration`` and advance drives and mechanics.

        Parameters
        ----------
        dac_volts : ndarray, shape (2,)
            Requested speed references (V); quantised to the DAC's codes and clipped to its
            range (flagged in the status).
        duration : float
            Time to advance (s): a positive multiple of :attr:`drive_dt`.

        Returns
        -------
        StepStatus

        Raises
        ------
        SimulationError
            If ``dac_volts`` is not finite, or the state diverges (not finite).
        ValueError
            If the shapes or ``duration`` are wrong.
        """
        dac_in = dac_volts if type(dac_volts) is np.ndarray and dac_volts.dtype == np.float64 \
            else np.asarray(dac_volts, dtype=np.float64)
        if dac_in.shape != (2,):
            raise ValueError(f"dac_volts must have 2 entries, got shape {dac_in.shape}")
        n = self._intervals.get(duration) or self._count_intervals(duration)
        if len(self._samples) < n:
            self._samples = np.empty((n, FINE_WIDTH))
        samples = self._samples[:n]
        steps = self._no_steps
        if self.accelerometer is not None:
            if len(self._steps) < n * self._substeps:
                self._steps = np.empty((n * self._substeps, 2))
            steps = self._steps[:n * self._substeps]
        m, d, k, u, x = self.model, self.data, self._substeps, self._u, self._table_pos
        omega, theta, drives, extent = self._rotor_vel, self._rotor_pos, self.drives, self._extent
        t0 = d.time
        params, state, tables, noise, log, sub, scratch = drives.kernel_arrays()
        if self._compiled:
            block = self._noise_block
            if drives.noisy:
                block = self._rng.standard_normal((n, *noise.shape))
            done, status, clip = plant_loop.step_intervals(
                *self._addresses, n, k, params, state, tables, dac_in, self._dac, u, block,
                log, drives.n_step, drives.dt, drives.enabled, self._passive,
                self._has_passive, self._chain, self._has_chain, self._drive_torque, sub,
                scratch, self._torque, self._slide_force, x, self._table_vel, theta, omega,
                *self._mj_arrays, self._spring_adr, self._spring_ratio, samples, steps,
                extent, self._ring, self._ring_n, self._out)
            if clip < 0:
                self._not_finite(dac_in)
            drives.advance(done)
            self._ring_n += done
            if status:
                drives.step(u, omega, theta)  # the checked path raises the named error
        else:
            clip = plant_loop.quantise(dac_in, self._dac, u)
            if clip < 0:
                self._not_finite(dac_in)
            mj_step = mujoco.mj_step
            for i in range(n):
                drives.step_into(u, omega, self._drive_torque, theta)
                for s in range(k):
                    plant_loop.apply_forces(self._passive, self._has_passive, self._chain,
                                            self._has_chain, sub, s, self._torque,
                                            self._slide_force, x, self._table_vel, theta,
                                            omega, *self._mj_arrays)
                    mj_step(m, d)
                    if len(steps):
                        steps[i * k + s] = self._table_vel
                plant_loop.record_interval(i, drives.time, state, x, d.qpos, self._spring_adr,
                                           self._spring_ratio,
                                           samples, extent, self._ring, self._ring_n)
            self._ring_n += n
            plant_loop.readout(state, self._out)
        if len(steps):
            self.accelerometer.feed(t0, self.model.opt.timestep, steps)  # type: ignore[union-attr]
        return self._checked(t0, samples, clip)

    def _checked(self, t0: float, samples: np.ndarray, clip: int) -> StepStatus:
        """The end of a step that started at ``t0`` and left the drive-rate ``samples``
        (their extent in ``self._extent``): the readers' drive state, the MuJoCo warnings
        and the divergence check (raises ``SimulationError``), the switches, the status."""
        d, extent = self.data, self._extent
        saturated = FLAGS[2 * (clip & 1) + (clip >> 1 & 1)]  # x then y
        self._ro = ro = self._out.tolist()
        self._fine = samples
        warnings = () if self._warning_count.tobytes() == self._warnings_seen \
            else self._new_warnings()
        lo_x, hi_x, lo_y, hi_y = extent.tolist()
        if not math.isfinite(lo_x + hi_x + lo_y + hi_y) or any(w in _BAD_STATE
                                                              for w in warnings):
            raise SimulationError(f"the plant state diverged by t = {d.time:.6f} s: "
                                  f"{self._diverged(extent)} (MuJoCo warnings: "
                                  f"{', '.join(warnings) or 'none'})")
        fault_x, fault_y = ro[2] != 0.0, ro[3] != 0.0
        mon_x, mon_y = self._monitors
        hit_x, end_x = mon_x.quick(lo_x, hi_x) or mon_x.update(samples[:, 0].tolist(), t0,
                                                               self.drive_dt)
        hit_y, end_y = mon_y.quick(lo_y, hi_y) or mon_y.update(samples[:, 1].tolist(), t0,
                                                               self.drive_dt)
        return StepStatus(saturated, FLAGS[2 * hit_x + hit_y], FLAGS[2 * end_x + end_y],
                          FLAGS[2 * fault_x + fault_y], warnings, d.time)

    def run_open_loop(self, dac_volts: np.ndarray, enable: np.ndarray,
                      intervals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Run a recorded open-loop sequence of ticks: each tick k samples the sensors
        (:meth:`read_into`), sets the drive enable to ``enable[k]`` (:meth:`enable`), then
        applies ``dac_volts[k]`` for ``intervals[k]`` drive intervals (:meth:`step`).

        The result is that of those calls, bit for bit (``tests/plant/test_fast_paths.py``);
        without sensor noise, the accelerometer or the Python loop (``loop.available()``)
        it is those calls. Otherwise the ticks run in the compiled loop
        (``loop.ticks``), which hands back to :meth:`step`'s own checks (switches near
        an edge, MuJoCo warnings, divergence) and :meth:`enable` the ticks that need them;
        the step statuses are not returned (an open loop does not act on them).

        Parameters
        ----------
        dac_volts : ndarray, shape (n, 2)
            Each tick's requested speed references (V).
        enable : ndarray, shape (n,)
            Each tick's drive enable (bool).
        intervals : ndarray, shape (n,)
            Each tick's duration in drive intervals (≥ 1).

        Returns
        -------
        counts : ndarray, shape (n, 2), int64
            The encoder counters at each tick's start (counts).
        tacho : ndarray, shape (n, 2)
            The tacho volts at each tick's start (V).

        Raises
        ------
        SimulationError
            As :meth:`step`.
        """
        n = len(intervals)
        counts, tacho = np.empty((n, 2), np.int64), np.empty((n, 2))
        lengths = np.ascontiguousarray(intervals, dtype=np.int64)
        if n and lengths.min() < 1:
            raise ValueError("every tick must last at least one drive interval")
        if not self._compiled or self._noisy_counts or self.drives.noisy \
                or self.accelerometer is not None:
            inputs = Inputs()
            for k in range(n):
                self.read_into(inputs)
                counts[k], tacho[k] = inputs.encoder_counts, inputs.tacho_volts
                if bool(enable[k]) != self.drives.enabled:
                    self.enable(bool(enable[k]))
                self.step(dac_volts[k], int(lengths[k]) * self.drive_dt)
            return counts, tacho
        self._run_compiled(np.ascontiguousarray(dac_volts, dtype=np.float64),
                           np.ascontiguousarray(enable, dtype=np.bool_), lengths, counts,
                           tacho)
        return counts, tacho

    def _run_compiled(self, dac: np.ndarray, enable: np.ndarray, lengths: np.ndarray,
                      counts: np.ndarray, tacho: np.ndarray) -> None:
        """:meth:`run_open_loop` in the compiled loop (no noise, no accelerometer)."""
        if len(self._samples) < lengths.max(initial=1):
            self._samples = np.empty((int(lengths.max()), FINE_WIDTH))
        drives, d, k = self.drives, self.data, 0
        params, state, tables, _, log, sub, scratch = drives.kernel_arrays()
        cpr = np.array(self._cpr)
        mask = np.array(self._mask, np.int64)
        clock = np.array([d.time, d.time])
        seen = np.frombuffer(self._warnings_seen, dtype=self._warning_count.dtype)
        while k < len(lengths):
            free = np.array([mon.free for mon in self._monitors])
            k, done, reason, _status, clip = plant_loop.ticks(
                k, lengths, dac, enable, drives.enabled, cpr,
                np.array(self._offset, np.int64), mask, free, self._warning_count, seen,
                clock, self.model.opt.timestep, counts, tacho, *self._addresses,
                self._substeps, params, state, tables, self._dac, self._u, self._noise_block,
                log, drives.n_step, drives.dt, self._passive, self._has_passive,
                self._chain, self._has_chain, self._drive_torque, sub, scratch, self._torque,
                self._slide_force, self._table_pos, self._table_vel, self._rotor_pos,
                self._rotor_vel, *self._mj_arrays, self._spring_adr, self._spring_ratio,
                self._samples, self._no_steps, self._extent, self._ring, self._ring_n,
                self._out)
            drives.advance(done)
            self._ring_n += done
            if reason == plant_loop.TICK_ENABLE:
                self.enable(bool(enable[k]))
                continue
            if reason == plant_loop.TICK_ERROR:
                if clip < 0:
                    self._not_finite(dac[k])
                drives.step(self._u, self._rotor_vel, self._rotor_pos)  # raises, named
            if reason in (plant_loop.TICK_ERROR, plant_loop.TICK_CHECK):
                self._checked(float(clock[0]), self._samples[:int(lengths[k])], clip)
                seen = np.frombuffer(self._warnings_seen, dtype=self._warning_count.dtype)
                k += 1
        self._ro = self._out.tolist()
        self._fine = self._samples[:int(lengths[-1])] if len(lengths) else self._fine

    def _diverged(self, extent: np.ndarray) -> str:
        """Which axis and which quantity left the finite numbers first (for the message)."""
        m, d = self.model, self.data
        for ax, (lo, hi) in zip(AXES, extent.reshape(2, 2).tolist(), strict=True):
            if not math.isfinite(lo + hi):
                return f"axis {ax}: the table position is not finite"
        for j in range(m.njnt):
            name = m.joint(j).name
            q, v = d.qpos[m.jnt_qposadr[j]], d.qvel[m.jnt_dofadr[j]]
            for what, value in (("position", q), ("velocity", v)):
                if not math.isfinite(value) or abs(value) > 1e9:
                    axis = name.split("_", 1)[0]
                    return f"axis {axis}: the {what} of joint {name} is {value:g}"
        return "a MuJoCo state warning (no state is yet non-finite)"

    # ------------------------------------------------------------------ sensing
    def read_into(self, inputs: Inputs, *, accelerometer: bool = True) -> None:
        """Sample the I/O into ``inputs`` in place, as the machine's I/O hardware delivers
        it: encoder counters (with their noise, wrapped to the counter's bits), tacho
        voltages at the ADC, debounced switches, drive ready, the plant time, and the
        accelerometer's FIFO when one is mounted and ``accelerometer`` (reading empties it;
        False leaves it for a reader of its own, the HIL module's registers). The one read
        path (:meth:`read` returns a new sample of it)."""
        counts = self._raw_counts()
        if self._noisy_counts:
            noise = np.rint(self._rng.standard_normal(2) * self._encoder_noise).tolist()
            counts = [c + int(n) for c, n in zip(counts, noise, strict=True)]
        offset, mask = self._offset, self._mask
        out = inputs.encoder_counts
        out[0] = (counts[0] + offset[0]) & mask[0]
        out[1] = (counts[1] + offset[1]) & mask[1]
        ro = self._ro
        tacho = inputs.tacho_volts
        tacho[0], tacho[1] = ro[0], ro[1]
        for k, mon in enumerate(self._monitors):
            inputs.limit_min[k], inputs.limit_max[k], inputs.home[k] = mon.state
        inputs.drive_ready = ro[2] == 0.0 and ro[3] == 0.0
        inputs.time = self.data.time
        sensor = self.accelerometer
        if sensor is None or not accelerometer:
            inputs.accel_count = 0
            return
        if inputs.accel_samples.shape != (sensor.config.block, 2):
            inputs.accel_samples = np.zeros((sensor.config.block, 2))
        inputs.accel_count, inputs.accel_sequence, inputs.accel_overrun = sensor.pop(
            inputs.accel_samples)
        inputs.accel_clock = self.data.time * sensor.config.sample_rate

    def read(self, *, accelerometer: bool = True) -> Inputs:
        """A new I/O sample (`twin.controller.io.Inputs`; see :meth:`read_into`)."""
        inputs = Inputs()
        self.read_into(inputs, accelerometer=accelerometer)
        return inputs

    @property
    def fine(self) -> np.ndarray:
        """The last :meth:`step`'s drive-rate samples, shape (intervals, ``FINE_WIDTH``),
        columns ``FINE_FIELDS`` (x then y each), one row at the end of every drive interval:
        what a scope on the drive would show (the converter's pulses, discontinuous
        current, the screw's elastic oscillation). A view, valid until the next step."""
        return self._fine

    def drain_fine(self) -> np.ndarray:
        """The drive-rate samples (rows of ``FINE_FIELDS``) written since the last drain, in
        order: at most the ring's ``FINE_RING`` rows (older ones are overwritten if nobody
        drains; the run loop drains every few dozen periods)."""
        n = self._ring_n - self._ring_read
        cap = len(self._ring)
        n = min(n, cap)
        start = (self._ring_n - n) % cap
        self._ring_read = self._ring_n
        if start + n <= cap:
            return self._ring[start:start + n].copy()
        return np.concatenate((self._ring[start:], self._ring[:start + n - cap]))

    def truth_row(self) -> tuple[float, ...]:
        """The ``TRUTH_FIELDS`` of now as one flat row of floats (cheap: for per-tick
        recording)."""
        x, v, q = self._table_pos.tolist(), self._table_vel.tolist(), self.data.qpos
        (r0, r1, a0, a1), ro = self._spring_f, self._ro
        return (x[0], x[1], v[0], v[1], r0 * float(q[a0]) - x[0], r1 * float(q[a1]) - x[1],
                ro[4], ro[5], ro[6], ro[7])

    def truth(self) -> Truth:
        """The full state of the twin (see :class:`Truth`)."""
        dr = self.drives
        return Truth(table_position=self._table_pos.copy(),
                     table_velocity=self._table_vel.copy(),
                     rotor_angle=self._rotor_pos.copy(), rotor_speed=self._rotor_vel.copy(),
                     screw_deflection=self._spring_ratio * self.data.qpos[self._spring_adr]
                     - self._table_pos,
                     armature_current=dr.current, converter_voltage=dr.output_voltage,
                     firing_angle=dr.firing_angle, bridge=dr.bridge,
                     speed_reference=dr.speed_reference, time=self.time)

    # ------------------------------------------------------------------ internals
    def _not_finite(self, dac_volts: np.ndarray) -> None:
        """Raise the ``SimulationError`` that names the axis whose request is not finite."""
        for a in (0, 1):
            v = float(dac_volts[a])
            if not math.isfinite(v):
                raise SimulationError(f"dac_volts[{a}] ({AXES[a]}) must be finite, got {v} at "
                                      f"t = {self.time:.6f} s")

    def _count_intervals(self, duration: float) -> int:
        """Drive intervals in ``duration`` (cached), which must be a positive multiple."""
        n = round(duration / self.drive_dt) if math.isfinite(duration) else 0
        if n < 1 or abs(n * self.drive_dt - duration) > 1e-9 * self.drive_dt:
            raise ValueError(f"duration must be a positive multiple of the drive interval "
                             f"{self.drive_dt} s, got {duration!r}")
        self._intervals[duration] = n
        return n

    def _raw_counts(self) -> list[int]:
        """The rotors' angles in whole encoder counts (no offset, no wrap)."""
        theta = self._rotor_pos.tolist()
        return [math.floor(theta[0] * self._cpr[0]), math.floor(theta[1] * self._cpr[1])]

    def _new_warnings(self) -> tuple[str, ...]:
        """Names of the MuJoCo warnings whose counters moved since the last call."""
        before = np.frombuffer(self._warnings_seen, dtype=self._warning_count.dtype)
        self._warnings_seen = self._warning_count.tobytes()
        return tuple(_WARNING_NAMES[i] for i in np.flatnonzero(self._warning_count != before))


def _pair_slices(m: mujoco.MjModel, joints: list[str] | tuple[str, ...]) -> tuple[slice, slice]:
    """qpos and dof slices of two adjacent one-dof joints (zero-copy views of the data)."""
    qadr = [int(m.joint(j).qposadr[0]) for j in joints]
    dadr = [int(m.joint(j).dofadr[0]) for j in joints]
    if qadr[1] != qadr[0] + 1 or dadr[1] != dadr[0] + 1:
        raise SimulationError(f"joints {joints} must be adjacent in the model")
    return slice(qadr[0], qadr[0] + 2), slice(dadr[0], dadr[0] + 2)
