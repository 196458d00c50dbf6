"""The cyclic CNC controller: one ``tick(inputs) -> outputs`` per position-loop period.

Each tick runs, in this order (seed 000's single-PC loop):

1. encoder unwrap: raw counters → table position (m);
2. safety: limit switches, drive ready;
3. interpolation: the next reference (position, velocity, acceleration, jerk) of the
   planned program (`Interpolator` over `Planner.plan`);
4. regulation: PID + FF1..FF3 + DCU (`PositionRegulator`), saturation, DAC quantisation;
5. outputs — the DAC values computed in the *previous* tick (compute ahead, as seed 000's
   rig did: the delay from sample to drive is exactly one period on any driver, which is
   what the DCU and the gain rules are derived for) — and one row of the record.

The cyclic path never raises for expected conditions; it reports a `ControllerStatus`:

* a limit switch that closes, or a reference moving toward a closed one → ``LIMIT_TRIP``;
* a following error beyond the limit → ``FOLLOWING_ERROR``; NaN inputs → ``INVALID_INPUT``;
* the drive reporting not ready → ``DRIVE_FAULT``;
* a G-code or soft-limit error met while streaming → the blocks before it run out (they end
  at rest), then ``PROGRAM_ERROR`` (``Controller.error`` holds the exception).

Each of these latches with the outputs at zero and the drives disabled until ``reset()``.

End of program: the loop stays closed on the end point (``SETTLING``; the record then shows
how the table comes to rest) for at least ``settle_time`` and until every axis' following
error is within ``in_position_tolerance`` (at most ``settle_timeout``), then the outputs go
to zero and the drives are disabled (``FINISHED``). A lead-screw table holds its position
without torque, and a disabled drive cannot oscillate.

Soft limits: a program held in memory (``Program``, list, tuple) is checked against the
work zone in the constructor, which raises ``PlanningError`` naming the G-code line before
any motion; a streamed program is checked block by block as it is planned.

Manual mode (issue 4, `twin.controller.manual`): ``jog(target)`` runs a single planned move
when the controller is at rest; ``home(axis)`` moves toward the home switch until it closes,
brakes, and declares the latched position to be the configured home position;
``test_signal`` follows a raw step or ramp (``twin experiment``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from twin.config import AXES, AxisConfig, ControllerSettings, MachineConfig
from twin.controller.compensation import (
    NO_COMPENSATION,
    ReferenceCompensation,
    compensation_table,
    curve_quartic,
    curve_step_acceleration,
    loop_variance,
)
from twin.controller.corner import CornerModel, NoCornerLimit
from twin.controller.cyclic import FALLBACK, steady_tick, warm_up
from twin.controller.encoder import EncoderUnwrapper
from twin.controller.gains import RegulatorGains
from twin.controller.gcode.items import Move
from twin.controller.interpolator import Interpolator, InterpolatorStatus
from twin.controller.io import Inputs, MachineIO, Outputs
from twin.controller.linear import LinearAxisModel
from twin.controller.loop_defaults import default_corner_model, estimated_axis_model, loop_gains
from twin.controller.manual import ManualCommands
from twin.controller.planner import MotionBlock, PlannedBlock, Planner
from twin.controller.record import Record
from twin.controller.regulator import PositionRegulator, RegulatorStatus
from twin.controller.shaped_corner import ShapedCornerModel, curve_acceleration
from twin.controller.shaping import NO_TAPS, InputShaper, ReferenceShaper, axis_shapers
from twin.controller.status import INTEGER_FIELDS, RECORD_FIELDS, ControllerStatus
from twin.errors import ConfigError, PlanningError, TwinError

__all__ = ["RECORD_FIELDS", "Controller", "ControllerStatus"]


_STATUS = tuple(ControllerStatus)
_REG_STATUS = tuple(RegulatorStatus)
_START_TOLERANCE = 1e-6
"""Largest distance (m) between the table and the first point of a program it may run."""
_FAULTS = {RegulatorStatus.FOLLOWING_ERROR: ControllerStatus.FOLLOWING_ERROR,
           RegulatorStatus.INVALID_INPUT: ControllerStatus.INVALID_INPUT}


def _shaped_planning(settings: ControllerSettings, shaper: ReferenceShaper
                     ) -> dict[str, Any]:
    """The planner's options an active shaper asks for: exact stops wait its duration,
    curves are capped so that it cuts them within its share of the contour tolerance; with
    the smoothing compensation only its fourth-order error and its transients at curvature
    steps are left to cap."""
    tolerance, share = settings.contour_tolerance, settings.shaper.curve_share
    out: dict[str, Any] = {
        "stop_dwell": shaper.duration,
        "curve_acceleration": curve_acceleration(shaper.shapers, tolerance, share)}
    if settings.compensation.smoothing:
        out["curve_quartic"] = curve_quartic(shaper.shapers, tolerance, share)
        out["curve_step"] = curve_step_acceleration(shaper.shapers, tolerance, share)
    return out


class Controller(ManualCommands):
    """The cyclic controller of a two-axis table (see the module docstring).

    Parameters
    ----------
    settings : ControllerSettings
        Period, limits, planner and regulator settings.
    axes : mapping of "x", "y" to AxisConfig
        The axes (limits, encoder, DAC, switches, travel).
    program : Program, iterable or None
        G-code items (``Program``, ``gcode.read_file``), ``MotionBlock``s, already
        ``PlannedBlock``s, or None to start idle (for ``jog``/``home``).
    gains : RegulatorGains, optional
        Default: ``settings.regulator`` with the unset gains from ``default_gains`` of the
        axis models (``loop_defaults.loop_gains``).
    axis_models : sequence of 2 LinearAxisModel, optional
        Reference (V) → position (m) models for the gain rules and the DCU; default
        ``loop_defaults.estimated_axis_model`` of each of ``model_axes``.
    model_axes : mapping of "x", "y" to AxisConfig, optional
        The axes as the controller believes them to be (its model of the machine: the
        mechanics for the corner model, the drives for the default axis models); default
        ``axes``, the machine itself. ``axes`` stays the machine's I/O (encoder, DAC,
        switches, travel, limits).
    profile : str, optional
        Acceleration law; default ``settings.profile``.
    planner : str, optional
        ``"lookahead"`` or ``"stop"``; default ``settings.planner``.
    dcu_order : int, optional
        0 … 3; default ``settings.regulator.dcu_order`` (ignored when ``gains`` is given).
    mode : {"extended", "traditional"}
        Interpolator interface (seed 004).
    corner_model : CornerModel, optional
        For the planner; default the seed-001 model of these axes with the servo time
        constant of the regulator (``loop_defaults.default_corner_model``). With shapers,
        the planner gets it plus the corner the shapers cut
        (``shaped_corner.ShapedCornerModel``) and caps the centripetal acceleration on
        curves (``shaped_corner.curve_acceleration``); not with a ``NoCornerLimit``.
    lookahead : int, optional
        Window (blocks); default ``settings.lookahead``.
    planner_options : mapping, optional
        More keyword options of ``Planner.from_settings`` (e.g. ``blend=0.0`` and
        ``period=None`` for a study of sharp corners passed at a chosen speed).
    start : sequence of 2 float, optional
        Table position at the first tick (m); default the program's start point.
    shapers : sequence of 2 InputShaper or None, optional
        The input shapers of x and y (``twin.controller.shaping``; None in the pair: that
        axis unshaped); default ``settings.shaper``, its unset frequency and damping from
        the believed axes (``shaping.axis_shapers``). They filter the interpolator's
        reference (not a test signal's) before the regulator and the record.
    settle_time : float
        Shortest closed-loop hold after the motion ends (s), at least the shapers' delay;
        the hold then lasts until the table is in position
        (``settings.in_position_tolerance``, at most ``settings.settle_timeout``).
    record_capacity : int
        Rows per chunk of the record.
    compiled : bool
        Run the steady ticks (moving along or dwelling in one block, no switch closed, drives
        ready, not homing, the extended interface) in one compiled kernel
        (``cyclic.steady_tick``); every other tick, and every tick with False, takes the
        plain Python path, the reference the kernel reproduces bit for bit.

    Raises
    ------
    PlanningError
        An in-memory program leaves the work zone, or does not start at ``start`` (naming
        its line).
    ConfigError
        An invalid option.
    """

    def __init__(self, settings: ControllerSettings, axes: Mapping[str, AxisConfig],
                 program: Iterable[Any] | None, *, gains: RegulatorGains | None = None,
                 axis_models: Sequence[LinearAxisModel] | None = None,
                 model_axes: Mapping[str, AxisConfig] | None = None,
                 profile: str | None = None, planner: str | None = None,
                 dcu_order: int | None = None, mode: str = "extended",
                 corner_model: CornerModel | None = None, lookahead: int | None = None,
                 planner_options: Mapping[str, Any] | None = None,
                 shapers: Sequence[InputShaper | None] | None = None,
                 start: Sequence[float] | None = None, settle_time: float = 0.25,
                 record_capacity: int = 65536, compiled: bool = True):
        if sorted(axes) != sorted(AXES):
            raise ConfigError("axes", f"must be {AXES}, got {tuple(axes)}")
        if not (math.isfinite(settle_time) and settle_time >= 0.0):
            raise ConfigError("settle_time", f"must be >= 0 (s), got {settle_time!r}")
        self.settings = settings
        self.axes = [axes[a] for a in AXES]
        self.period = settings.period
        self.mode = mode
        self.settle_time = float(settle_time)
        self._in_position = settings.in_position_tolerance
        self._settle_timeout = max(settings.settle_timeout, self.settle_time)
        believed = axes if model_axes is None else model_axes
        if sorted(believed) != sorted(AXES):
            raise ConfigError("model_axes", f"must be {AXES}, got {tuple(believed)}")
        models = list(axis_models) if axis_models is not None else [
            estimated_axis_model(believed[a]) for a in AXES]
        if gains is None:
            order = settings.regulator.dcu_order if dcu_order is None else dcu_order
            gains = loop_gains(settings, self.axes, models, order)
        self.gains = gains
        if corner_model is None:
            corner_model = default_corner_model(settings, axes, model_axes=believed,
                                                axis_models=models, gains=gains)
        if shapers is None:
            shapers = axis_shapers(settings.shaper, believed, self.period)
        shaper = ReferenceShaper(shapers, self.period)
        shaped: dict[str, Any] = {}
        comp = settings.compensation
        loop = ([loop_variance(models[k], gains, self.period, k) for k in range(2)]
                if comp.smoothing else [0.0, 0.0])
        self.compensation = ReferenceCompensation(
            compensation_table(comp, believed, shaper.shapers, loop, self.period),
            self.period)
        """ReferenceCompensation: the reference's offsets (``settings.compensation``)."""
        if shaper.active and not isinstance(corner_model, NoCornerLimit):
            corner_model = ShapedCornerModel(corner_model, shaper.shapers)
            shaped = _shaped_planning(settings, shaper)
        options: dict[str, Any] = {"law": profile or settings.profile,
                                   "mode": planner or settings.planner,
                                   "lookahead": lookahead or settings.lookahead,
                                   "corner_model": corner_model, **shaped,
                                   **(planner_options or {})}
        self.planner = Planner.from_settings(settings, axes, **options)
        """Planner: the look-ahead planner (its ``work_zone`` holds the soft limits)."""
        self._free_planner = Planner.from_settings(settings, axes, **options, work_zone=None)
        self.regulator = PositionRegulator(gains, self.period, n_axes=2)
        self.shaper: ReferenceShaper | None = shaper if shaper.active else None
        """ReferenceShaper or None: the input shapers of the position reference."""
        if self.shaper is not None:
            self.settle_time = max(self.settle_time, self.shaper.duration + self.period)
        self.encoder = EncoderUnwrapper([ax.counts_per_metre for ax in self.axes],
                                        bits=[ax.encoder.bits for ax in self.axes])
        self.record = Record(RECORD_FIELDS, integer=INTEGER_FIELDS, capacity=record_capacity)
        """Record: one row per tick, fields ``RECORD_FIELDS``; ``record.as_arrays()``."""
        self.outputs = Outputs()
        """Outputs: written in place and returned by every ``tick``."""
        self._held = np.zeros(2)
        self.error: TwinError | None = None
        """The exception behind ``PROGRAM_ERROR``, if any."""
        self.status = ControllerStatus.IDLE
        self._ticks = 0
        self._settled = 0.0
        self._limits_prev = np.zeros(4, dtype=bool)
        self._homing: tuple[int, float] | None = None
        self._home_latch: float | None = None
        # the kernel's integer arithmetic unwraps counters of up to 62 bits
        self.compiled = bool(compiled) and mode == "extended" and all(
            ax.encoder.bits <= 62 for ax in self.axes)
        if self.compiled:
            warm_up()
        self._read_ahead_in_tick = True
        self.interpolator = self._interpolator(self._blocks(program, start), start)
        if program is not None:
            self.status = ControllerStatus.RUNNING
        self._start = [float(p) for p in self.interpolator.reference.position]
        if self.shaper is not None:
            self.shaper.reset(self._start)
        self.compensation.reset()

    @classmethod
    def from_machine(cls, cfg: MachineConfig, program: Iterable[Any] | None,
                     **options: Any) -> Controller:
        """A controller for a whole machine configuration; options as the constructor's."""
        return cls(cfg.controller, cfg.axes, program, **options)

    # ------------------------------------------------------------------ set-up helpers
    def _blocks(self, program: Iterable[Any] | None, here: Sequence[float] | None
                ) -> Iterable[Any]:
        """The planned blocks of ``program``; an in-memory one is checked first: the work
        zone, and that it starts where the table is (``here``, if known)."""
        if program is None:
            return ()
        if not (isinstance(program, Sequence) or hasattr(program, "items")):
            return self.planner.plan(program)
        items = list(program)
        first = next((i for i in items if isinstance(i, Move | MotionBlock | PlannedBlock)),
                     None)
        if first is not None and here is not None:
            begin = first.start if isinstance(first, Move) else first.segment.start
            if math.dist(begin, here) > _START_TOLERANCE:
                raise PlanningError(
                    f"line {first.line}: the program starts at ({begin[0]:.6g}, "
                    f"{begin[1]:.6g}) m but the table is at ({here[0]:.6g}, {here[1]:.6g}) "
                    "m; read it with start= the table position")
        if isinstance(first, PlannedBlock):
            return items
        self.planner.check(items)
        return self.planner.plan(items)

    def _interpolator(self, blocks: Iterable[Any], start: Sequence[float] | None
                      ) -> Interpolator:
        interp = Interpolator(blocks, period=self.period, start=start, mode=self.mode,
                              counts_per_metre=[ax.counts_per_metre for ax in self.axes],
                              tables=self.compiled)
        interp.read_ahead = self._read_ahead_in_tick
        return interp

    # ------------------------------------------------------------------ read-ahead
    @property
    def read_ahead_in_tick(self) -> bool:
        """Whether ``tick`` itself makes the interpolator's read-ahead step (default True).

        The read-ahead — the streamed planner's next chunk, the next block's speed profile
        and tables — is the bulk of the work of a tick that prepares a block. It does not
        feed the outputs of that tick. A real-time loop (``TickLoop``) sets this False and
        calls ``read_ahead`` after writing the outputs, as a CNC runs its block preparation
        beside the interpolation interrupt: the tick, read to write, stays short. The
        outputs are the same either way."""
        return self._read_ahead_in_tick

    @read_ahead_in_tick.setter
    def read_ahead_in_tick(self, flag: bool) -> None:
        self._read_ahead_in_tick = bool(flag)
        if isinstance(self.interpolator, Interpolator):
            self.interpolator.read_ahead = self._read_ahead_in_tick

    def read_ahead(self) -> None:
        """The interpolator's read-ahead, if any is due (see ``read_ahead_in_tick``); call
        it after writing a tick's outputs."""
        interp = self.interpolator
        if isinstance(interp, Interpolator):
            interp.prepare_next()

    # ------------------------------------------------------------------ the cyclic path
    def tick(self, inputs: Inputs) -> Outputs:
        """Run one period: read ``inputs``, compute and return the outputs (never raises
        for expected conditions; see ``status``)."""
        if self.compiled and self._tick_compiled(inputs):
            return self.outputs
        return self._tick_python(inputs)

    def _tick_compiled(self, inputs: Inputs) -> bool:
        """A steady tick in the compiled kernel; False (nothing changed) when this tick
        needs the Python path."""
        status = self.status
        if status is not ControllerStatus.RUNNING and status is not ControllerStatus.DWELLING:
            return False
        interp = self.interpolator
        cur = interp._cur
        if cur is None or self._homing is not None or self.regulator._latched:
            return False
        tau = interp._tau + interp.period
        passed = 0
        if not tau < cur.duration:
            # Block changes to blocks read ahead and activated are done here, as
            # ``Interpolator.update`` does them; anything else (an event, a dwell still to
            # start, a block not yet prepared) takes the Python path.
            landing = interp.landing(tau)
            if landing is None:
                return False
            passed, cur, tau = landing
        tables = cur.tables
        if tables is None or not self.encoder._ready:
            return False
        enc, reg, ref, rec = self.encoder, self.regulator, interp.reference, self.record
        chunk, row = rec.slot()
        geo, pieces, starts, table, coef = tables
        shaper = self.shaper
        taps = NO_TAPS if shaper is None else (shaper.index, shaper.weight, shaper.history,
                                               shaper.state)
        comp = self.compensation
        offsets = (comp.par, comp.state) if comp.active else NO_COMPENSATION
        code = steady_tick(
            inputs.encoder_counts, inputs.tacho_volts, inputs.limit_min, inputs.limit_max,
            bool(inputs.drive_ready), self._limits_prev, enc.state_int, enc.state_float,
            enc.position, geo, pieces, starts, table, coef, tau, self._ticks + 1,
            self.period, ref.position, ref.velocity, ref.acceleration, ref.jerk, *offsets,
            *taps, reg._par,
            reg._st, reg.output, reg.error, reg.terms, reg._code_min,
            reg._code_max, self._held, self.outputs.dac_volts, chunk, row, cur.index,
            cur.line)
        if code == FALLBACK:
            return False
        rec.advance()
        self._ticks += 1
        interp._ticks += 1
        if passed:
            interp.switch_blocks(passed, tau)
        else:
            interp._tau = tau
        ref.time = interp._ticks * interp.period
        ref.block, ref.line = cur.index, cur.line
        rcode = code >> 5
        reg.status = _REG_STATUS[rcode]
        if rcode >= RegulatorStatus.FOLLOWING_ERROR:
            reg._latched = reg.status
        self.status = status = _STATUS[code & 31]
        self.outputs.enable = status < ControllerStatus.FINISHED
        if not passed and interp.read_ahead:
            interp.prepare_next()              # as update(): none on a block change
        return True

    def _tick_python(self, inputs: Inputs) -> Outputs:
        """``tick`` in plain Python: every case, and the reference of the compiled path."""
        self._ticks += 1
        enc = self.encoder
        if not enc.ready:
            enc.reset(inputs.encoder_counts, position=self._start)
            self.regulator.reset(self._start)
            self._held[0] = self._held[1] = 0.0
        pos = enc.update(inputs.encoder_counts)
        status = self.status
        interp = self.interpolator
        reg = self.regulator
        ref = interp.reference
        if status < ControllerStatus.FINISHED:
            status = self._safety(inputs, ref.velocity)
        if status < ControllerStatus.FINISHED and status != ControllerStatus.IDLE:
            istatus = interp.update()
            if type(interp) is Interpolator:
                comp = self.compensation if self.compensation.active else None
                if comp is not None:
                    comp.apply(0, ref.position, ref.velocity, ref.acceleration, ref.jerk)
                if self.shaper is not None:
                    self.shaper.apply(ref.position, ref.velocity, ref.acceleration,
                                      ref.jerk)
                if comp is not None:
                    comp.apply(1, ref.position, ref.velocity, ref.acceleration, ref.jerk)
            rstatus = reg.update(ref.position, ref.velocity, ref.acceleration, ref.jerk, pos)
            if rstatus >= RegulatorStatus.FOLLOWING_ERROR:
                status = _FAULTS[RegulatorStatus(rstatus)]
            else:
                status = self._progress(status, istatus, inputs, pos)
        out = self.outputs
        if status < ControllerStatus.FINISHED and status != ControllerStatus.IDLE:
            # Compute ahead (seed 000): write what the previous tick computed, so the
            # reference reaches the drive exactly one period after its sample, whatever
            # the driver's timing. The DCU and the gain rules assume this delay.
            held = self._held
            out.dac_volts[0], out.dac_volts[1] = held
            out_now = reg.output
            held[0], held[1] = out_now[0], out_now[1]
            out.enable = True
        else:  # faults and the end stop at once: no held value survives
            out.dac_volts[:] = 0.0
            self._held[0] = self._held[1] = 0.0
            out.enable = False
        self.status = status
        self._log(pos, inputs, status)
        return out

    def _safety(self, inputs: Inputs, v_ref: Any) -> ControllerStatus:
        """Limit switches (rising edge, or moving toward a closed one) and drive ready."""
        if not inputs.drive_ready and self.status != ControllerStatus.IDLE:
            return ControllerStatus.DRIVE_FAULT
        lo, hi = inputs.limit_min, inputs.limit_max
        prev = self._limits_prev
        trip = False
        for k in (0, 1):
            a, b = bool(lo[k]), bool(hi[k])
            if (a and (not prev[2 * k] or v_ref[k] < 0.0)) or (
                    b and (not prev[2 * k + 1] or v_ref[k] > 0.0)):
                trip = True
            prev[2 * k], prev[2 * k + 1] = a, b
        return ControllerStatus.LIMIT_TRIP if trip else self.status

    def _progress(self, status: ControllerStatus, istatus: InterpolatorStatus,
                  inputs: Inputs, pos: Any) -> ControllerStatus:
        """Status after a healthy tick: running, homing, settling, finished."""
        if self._homing is not None and self._home_latch is None:
            k = self._homing[0]
            if inputs.home[k]:
                self._home_latch = float(pos[k])
                self.interpolator.stop()
            elif istatus >= InterpolatorStatus.FINISHED:
                self._homing = None
                return ControllerStatus.HOMING_FAILED
        if istatus < InterpolatorStatus.FINISHED:
            if self._homing is not None:
                return ControllerStatus.HOMING
            return (ControllerStatus.DWELLING if istatus == InterpolatorStatus.DWELLING
                    else ControllerStatus.RUNNING)
        if status != ControllerStatus.SETTLING:
            if self._homing is not None:
                self._finish_homing()
            self._settled = 0.0
            return ControllerStatus.SETTLING
        self._settled += self.period
        if self._settled < self.settle_time - 1e-12:
            return ControllerStatus.SETTLING
        err = self.regulator.error
        if (max(abs(float(err[0])), abs(float(err[1]))) > self._in_position
                and self._settled < self._settle_timeout - 1e-12):
            return ControllerStatus.SETTLING
        if istatus == InterpolatorStatus.ERROR:
            self.error = self.interpolator.error
            return ControllerStatus.PROGRAM_ERROR
        return ControllerStatus.FINISHED

    def _log(self, pos: Any, inputs: Inputs, status: ControllerStatus) -> None:
        ref = self.interpolator.reference
        reg = self.regulator
        # tolist(): one conversion per array instead of a numpy scalar per element
        self.record.append((
            self._ticks * self.period, *ref.position.tolist(), *ref.velocity.tolist(),
            *ref.acceleration.tolist(), *ref.jerk.tolist(), *pos.tolist(),
            *reg.error.tolist(), *self.outputs.dac_volts.tolist(),
            *inputs.tacho_volts.tolist(), *reg.terms.ravel().tolist(), self.outputs.enable,
            ref.block, ref.line, status))

    # ------------------------------------------------------------------ commands
    @property
    def done(self) -> bool:
        """True when the controller is at rest for good: finished, idle or tripped."""
        return self.status >= ControllerStatus.FINISHED or self.status == ControllerStatus.IDLE

    @property
    def position_reference(self) -> tuple[float, float]:
        """The current position reference (m)."""
        return tuple(float(p) for p in self.interpolator.reference.position)  # type: ignore

    def reset(self) -> None:
        """Clear a latched fault; the controller becomes IDLE at its present reference."""
        self.error = None
        self._homing = self._home_latch = None
        self._rest_at(self.position_reference)
        self.status = ControllerStatus.IDLE

    def _rest_at(self, here: Sequence[float], interpolator: Any = None) -> None:
        """Start from rest at ``here`` (m) with ``interpolator`` (or the reference source
        of a test signal; default an idle one there): the regulator's history and the
        output held for the next tick cleared."""
        self.interpolator = self._interpolator((), here) if interpolator is None \
            else interpolator
        self.regulator.reset(here)
        if self.shaper is not None:
            self.shaper.reset(here)
        self.compensation.reset()
        self._held[0] = self._held[1] = 0.0

    def run(self, io: MachineIO, *, max_time: float = math.inf) -> ControllerStatus:
        """Tick against ``io`` until ``done`` (or ``max_time`` of controller time, s)."""
        limit = math.inf if math.isinf(max_time) else round(max_time / self.period)
        n = 0
        while not self.done and n < limit:
            io.write(self.tick(io.read()))
            n += 1
        return self.status
