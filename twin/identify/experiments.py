"""Run the identification plan on a machine through ``MachineIO``, the controller's own port.

The same code runs on the twin (``SimDriver``, lock-step) and on real I/O (a Modbus module,
paced by ``RealTimeLoop``). Before the experiments each axis is moved, by the controller's
own planned jog, to a start point with room for the plan's excursion (``plan.excursion``)
inside the work zone. During them every tick is checked, and the run stops safely — outputs
zero, drives disabled — on:

- an end limit switch, or the drives reporting not ready;
- the table leaving the room it was given (the start ± the excursion, 1 mm inside the
  switches);
- a following error of the closed-loop pieces beyond the machine's limit.

Positions are the encoder counts over the model's counts per metre, taken as absolute as
``twin run`` does behind real I/O (a machine is homed first).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from twin.config import AXES, MachineConfig
from twin.controller.encoder import EncoderUnwrapper
from twin.controller.io import MachineIO, Outputs
from twin.controller.loop_defaults import loop_gains
from twin.controller.regulator import PositionRegulator, RegulatorStatus
from twin.drive.design import axis_inertia
from twin.errors import ConfigError, ExperimentAborted
from twin.hardware.realtime import RealTimeLoop, TickStats
from twin.identify.log import COLUMNS, IdentLog, io_signature
from twin.identify.plan import Piece, excursion, phases
from twin.session.machine_io import check_safe, move_to, safe_stop
from twin.session.run import axis_models, measured_position

__all__ = ["HOLD", "MARGIN", "REPEATS", "disturbed", "run_plan", "timing"]

MARGIN = 1e-3
"""Room kept between the experiments and the end switches (m)."""
HOLD = 0.1e-3
"""How far an axis that is not excited may move from where it is held (m)."""
REPEATS = 2
"""Real I/O: how many times a phase disturbed by the loop's timing (``disturbed``) is run
again; the least disturbed attempt is kept."""


def timing(notes: dict) -> str:
    """One line on a paced log's timing (its ``deadlines`` and ``repeated`` notes), for the
    messages that judge its fit; empty for a lock-step log."""
    reports = notes.get("deadlines", [])
    if not reports:
        return ""
    due = sum(r["due"] for r in reports)
    on_time = sum(r["on_time"] for r in reports)
    text = (f"the experiments' loop: {on_time} of {due} ticks on time, "
            f"{sum(r['skipped'] for r in reports)} slots lost, the latest tick "
            f"{max(r['jitter_max_us'] for r in reports) / 1e3:.2f} ms late")
    repeated = notes.get("repeated", [])
    return text + (f"; repeated for timing: {'; '.join(repeated)}" if repeated else "")


def disturbed(stats) -> bool:
    """Whether a paced phase's deadline report (``TickStats``) shows a timing fault that
    the fit cannot see: a lost slot, or a tick that started half a period late or more.
    The log records when each tick's read went out (``_Runner.paced_times``), but not
    when, inside a stalled tick, its write took effect, so such a phase is measured again
    rather than fitted."""
    return stats.skipped > 0 or stats.jitter_max_us >= 0.5e6 * stats.period


class _Runner:
    """The per-tick logic of one part of the plan (shared by lock-step and paced loops)."""

    def __init__(self, driver: MachineIO, base: MachineConfig, belief: MachineConfig,
                 pieces: Sequence[tuple[int, Piece]], window: Sequence[tuple[float, float]],
                 rows: list, moving: Sequence[bool] = (True, True)):
        self.driver, self.base = driver, base
        self.pieces = [p for p in pieces if p[1].kind != "home"]
        self.period = base.controller.period
        gains = loop_gains(base.controller, [base.axes[a] for a in AXES], axis_models(belief),
                           base.controller.regulator.dcu_order)
        self.regulator = PositionRegulator(gains, self.period)
        self.encoder = EncoderUnwrapper([base.axes[a].counts_per_metre for a in AXES],
                                        bits=[base.axes[a].encoder.bits for a in AXES])
        self.volts_per_speed = np.array([belief.axes[a].volts_per_speed for a in AXES])
        self.moving = np.array(moving, dtype=bool)
        self.window = list(window)
        ticks = [max(1, round(p.duration / self.period)) for _, p in self.pieces]
        self.piece_of_tick = np.repeat(np.arange(len(self.pieces)), ticks)
        self.rows = rows
        self.t0 = rows[-1][0] + self.period if rows else 0.0
        self.out = Outputs()
        self.held = np.zeros(2)
        self.ref = np.zeros(2)
        self.vel = np.zeros(2)
        self.zero = np.zeros(2)
        self.last_kind = ""
        self.t_ref = 0.0
        self.stamps: list[float] = []
        """The clock (``time.perf_counter``) when each tick's read went out: a paced
        part's rows take their time from it (``paced_times``)."""

    def start(self, counts, here: np.ndarray) -> None:
        """Take the table's position as the start: the encoder origin and the position
        loop's reference (an axis not excited is held there)."""
        self.encoder.reset(counts, position=here)
        self.ref[:] = here
        self.regulator.reset(here)

    def tick(self, k: int, t: float) -> bool:
        """Read, check, compute and write one tick; False when the part is done.

        The position loop runs every tick: it drives the ramps, and it holds an axis that
        is not excited (``moving`` False) where it started, through every piece. An
        excited axis takes the open-loop pieces' volts, its reference following the table
        so that the loop picks it up without a jump at the next ramp."""
        if k >= len(self.piece_of_tick):
            return False
        self.stamps.append(time.perf_counter())   # when the tick's I/O went out
        inputs = self.driver.read()
        pos = self.encoder.update(inputs.encoder_counts)
        index, piece = self.pieces[int(self.piece_of_tick[k])]
        self._check(inputs, pos, piece)
        enable = piece.kind != "coast"
        moving = self.moving
        if piece.kind == "ramp":
            if self.last_kind != "ramp":  # a ramp starts from where the table is
                self.ref[moving] = pos[moving]
                if moving.all():
                    self.regulator.reset(pos)
                    self.held[:] = 0.0
                self.t_ref = t
            self.vel[:] = np.where(moving, piece.value, 0.0)
            # the reference advances with the clock (a paced loop may skip a late slot)
            self.ref += self.vel * (t + self.period - self.t_ref)
            self.t_ref = t + self.period
        else:
            self.ref[moving] = pos[moving]
            self.vel[:] = 0.0
        self.last_kind = piece.kind
        status = self.regulator.update(self.ref, self.vel, self.zero, self.zero, pos)
        if status >= RegulatorStatus.FOLLOWING_ERROR:
            raise ExperimentAborted(
                f"{piece.experiment}: following error beyond the limit at t = {t:.3f} s "
                f"(x {1e6 * self.regulator.error[0]:.1f} µm, y "
                f"{1e6 * self.regulator.error[1]:.1f} µm)")
        dac = self.held.copy()          # compute ahead, as the controller does
        self.held[:] = self.regulator.output
        if piece.kind == "speed":
            dac[moving] = piece.value * self.volts_per_speed[moving]
        elif piece.kind == "coast":
            dac[:] = 0.0
        self.out.dac_volts[:] = dac
        self.out.enable = enable
        self.driver.write(self.out)
        self.rows.append((self.t0 + t, dac[0], dac[1], float(enable), inputs.encoder_counts[0],
                          inputs.encoder_counts[1], inputs.tacho_volts[0],
                          inputs.tacho_volts[1], float(inputs.home[0]), float(inputs.home[1]),
                          float(bool(np.any(inputs.limit_min) or np.any(inputs.limit_max))),
                          float(bool(inputs.drive_ready)), index))
        return True

    def paced_times(self, rows: list, first: int, start: float) -> None:
        """The time of this part's rows from ``first`` on: when each tick's read went out
        (``stamps``, relative to the loop's ``start``), no longer its slot's deadline. A
        tick that ran late read the machine late, and its DAC volts took over late: the
        previous tick's volts acted the longer (a machine's I/O module samples and applies
        when asked). Replayed with the deadlines, one tick 3.5 ms late over Modbus put the
        replay 30 µm off for the rest of its piece."""
        for i, stamp in enumerate(self.stamps[:len(rows) - first]):
            rows[first + i] = (self.t0 + (stamp - start), *rows[first + i][1:])

    def _check(self, inputs, pos, piece: Piece) -> None:
        check_safe(inputs, pos, self.window,
                   f"during {piece.experiment} at x {1e3 * pos[0]:.3f} mm, "
                   f"y {1e3 * pos[1]:.3f} mm", room="the experiments",
                   drives=piece.kind != "coast")

    def stop(self) -> None:
        """Safe stop: outputs zero, drives disabled."""
        safe_stop(self.driver, self.out)


def _position(driver: MachineIO, base: MachineConfig) -> np.ndarray:
    return measured_position(driver.read().encoder_counts, base)


def _room(base: MachineConfig, part: Sequence[Piece], here: np.ndarray,
          moving: Sequence[bool] = (True, True)
          ) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Where a part of the plan starts and each axis' window: a ``home`` piece's point, or
    the point nearest ``here`` with room for the part's excursion inside the switches. An
    axis not excited stays where it is, its window ``HOLD`` either side."""
    target = here.copy()
    window = []
    for k, a in enumerate(AXES):
        if not moving[k]:
            window.append((here[k] - HOLD, here[k] + HOLD))
            continue
        lo, hi = excursion(list(part), coast_travel=_coast_bound(base, a))
        sw = base.axes[a].switches
        safe_lo, safe_hi = sw.limit_min + MARGIN, sw.limit_max - MARGIN
        if part and part[0].kind == "home":
            target[k] = sw.home - 0.5 * sw.home_width + part[0].value
        elif safe_hi - safe_lo < hi - lo:
            raise ConfigError("amplitude", f"axis {a}: the experiments need "
                              f"{1e3 * (hi - lo):.1f} mm, the work zone holds "
                              f"{1e3 * (safe_hi - safe_lo):.1f} mm; lower --amplitude")
        else:
            target[k] = min(max(here[k], safe_lo - lo), safe_hi - hi)
        window.append((max(target[k] + lo - 0.5 * MARGIN, sw.limit_min),
                       min(target[k] + hi + 0.5 * MARGIN, sw.limit_max)))
    return target, window


SPREAD = 2.0
"""How far a machine of BASE's design may be from the model where it decides how far a
coast runs: up to ``SPREAD`` times the model's inertia and down to 1/``SPREAD`` of its
Coulomb and viscous friction, each (the fit's own inertia scan spans 0.5 … 2 times)."""


def _coast_bound(base: MachineConfig, axis: str) -> Callable[[float], float]:
    """How far axis ``axis``'s table may coast from table speed v (m/s) with its drive
    disabled: J·dω/dt = −(T_c + B·ω) from ω_0 = v/r runs the rotor through
    (J/B)·(ω_0 − (T_c/B)·ln(1 + B·ω_0/T_c)) (J·ω_0²/(2·T_c) without viscous friction),
    for a machine with ``SPREAD`` times the model's inertia and 1/``SPREAD`` of each of
    its frictions."""
    ax = base.axes[axis]
    m, r = ax.mechanics, ax.transmission.ratio
    inertia = SPREAD * axis_inertia(ax, base.moving_masses()[axis])
    torque = (m.rotor_coulomb + r * m.slide_coulomb) / SPREAD
    viscous = (m.rotor_viscous + r * r * m.slide_viscous) / SPREAD
    if torque <= 0.0 and viscous <= 0.0:
        return lambda v: 0.5 * float(np.diff(m.travel)[0])

    def travel(v: float) -> float:
        w = abs(v) / r
        if viscous <= 0.0:
            return r * inertia * w * w / (2.0 * torque)
        if torque <= 0.0:
            return r * inertia * w / viscous
        return r * inertia / viscous * (w - torque / viscous * math.log1p(viscous * w
                                                                          / torque))

    return travel


def run_plan(driver: MachineIO, base: MachineConfig, plan: Sequence[Piece], *,
             belief: MachineConfig | None = None, paced: bool = False,
             driver_name: str = "sim", progress: Callable[[float], None] | None = None,
             axes: Sequence[str] = AXES) -> IdentLog:
    """Run ``plan`` on the axes ``axes`` through ``driver`` and return the log; the other
    axis is held in position by the loop (within ``HOLD``).

    Parameters
    ----------
    driver : MachineIO
        The machine (opened; the caller closes it).
    base : MachineConfig
        The model the plan is scaled with, and the machine's I/O and limits.
    plan : sequence of Piece
    belief : MachineConfig, optional
        The controller's model for the closed-loop pieces and the jogs; default ``base``.
    paced : bool
        Real I/O: one tick per period of wall time (``RealTimeLoop``).
    driver_name : str
        Recorded in the log.
    progress : callable(seconds done), optional
    axes : sequence of str
        The axes to excite (both by default).

    Raises
    ------
    ExperimentAborted
        A safety stop; the machine was stopped (its outputs zero, drives disabled). The
        partial log is attached as ``exc.log``.
    ConfigError
        The work zone has no room for the plan.
    """
    belief = belief or base
    moving = [a in axes for a in AXES]
    rows: list[tuple] = []
    notes: dict = {}
    start = _position(driver, base)
    t_wall = time.perf_counter()
    index = 0
    for number, part in enumerate(phases(list(plan))):
        numbered = list(enumerate(part, start=index))
        index += len(part)
        kept = len(rows)
        best: tuple[tuple, list, np.ndarray] | None = None
        for attempt in range(1 + (REPEATS if paced else 0)):
            del rows[kept:]
            try:
                stats, here = _run_part(driver, base, belief, part, numbered, rows, moving,
                                        paced, progress)
            except ExperimentAborted as exc:
                exc.log = _log(rows, base, plan, start, driver_name, {"aborted": str(exc)},
                               axes)
                raise
            if stats is None:          # lock-step: no timing to judge
                best = ((), rows[kept:], here)
                break
            notes.setdefault("deadlines", []).append(
                {**stats.to_dict(), "phase": number, "attempt": attempt})
            score = (stats.skipped, stats.jitter_max_us)
            if best is None or score < best[0]:
                best = (score, rows[kept:], here)
            if not disturbed(stats):
                break
            notes.setdefault("repeated", []).append(
                f"phase {number}: {stats.skipped} slots lost, a tick "
                f"{stats.jitter_max_us / 1e3:.2f} ms late")
        assert best is not None
        rows[kept:] = best[1]          # the least disturbed attempt
        if kept == 0:
            start = best[2]
    notes["wall_time_s"] = time.perf_counter() - t_wall
    notes["machine_time_s"] = len(rows) * base.controller.period
    return _log(rows, base, plan, start, driver_name, notes, axes)


def _run_part(driver: MachineIO, base: MachineConfig, belief: MachineConfig,
              part: Sequence[Piece], numbered: Sequence[tuple[int, Piece]], rows: list,
              moving: Sequence[bool], paced: bool,
              progress: Callable[[float], None] | None) -> tuple[TickStats | None, np.ndarray]:
    """Move to the part's start point and run it, appending its rows: (the deadline
    report, None lock-step; where the table started, m). The machine is stopped (outputs
    zero, drives disabled) however it ends."""
    target, window = _room(base, part, _position(driver, base), moving)
    move_to(driver, base, belief, target, paced)
    runner = _Runner(driver, base, belief, numbered, window, rows, moving)
    counts = driver.read().encoder_counts
    here = measured_position(counts, base)
    runner.start(counts, here)
    runner.stop()  # a clean enable edge: the drives start from their reset state
    stats = None
    try:
        if paced:
            loop = RealTimeLoop(base.controller.period)
            first = len(rows)
            stats = loop.run(runner.tick)
            runner.paced_times(rows, first, loop.start)
        else:
            k = 0
            while runner.tick(k, k * base.controller.period):
                k += 1
                if progress is not None and k % 200 == 0:
                    progress(len(rows) * base.controller.period)
    finally:
        runner.stop()
    return stats, here


def _log(rows: list[tuple], base: MachineConfig, plan: Sequence[Piece], start: np.ndarray,
         driver_name: str, notes: dict, axes: Sequence[str]) -> IdentLog:
    table = np.array(rows, dtype=float).reshape(-1, len(COLUMNS))
    data = {c: table[:, i].copy() for i, c in enumerate(COLUMNS)}
    return IdentLog(base.name, io_signature(base), driver_name, list(plan), data,
                    [float(v) for v in start], notes, [a for a in AXES if a in axes])
