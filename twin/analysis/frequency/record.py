"""Running the excitation on a machine through ``MachineIO`` and recording it, safely.

The measured axis moves at the offset speed with the excitation on top; the other axis is
held in position by the position loop. With ``loop`` ``speed`` or ``mechanics`` the
measured axis' position loop is open: its DAC gets the offset's volts plus the excitation
(the drive's own speed loop stays closed). With ``position`` the loop is closed: the
reference ramps at the offset speed and the excitation is added to the regulator's output
at the DAC, where the loop is opened for the measurement.

Every tick is checked, as in ``twin identify``, and the run stops safely (outputs zero,
drives disabled) on an end limit switch, the drives reporting not ready, the table leaving
the room it was given, or a following error beyond the machine's limit (the regulator,
which runs every tick, trips on it; with the position loop open its reference follows the
ramp the offset asks for, so a drive that runs away is caught as well).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from twin.config import AXES, MachineConfig
from twin.controller.encoder import EncoderUnwrapper
from twin.controller.io import MachineIO, Outputs
from twin.controller.loop_defaults import loop_gains
from twin.controller.regulator import PositionRegulator, RegulatorStatus
from twin.errors import ExperimentAborted
from twin.hardware.realtime import RealTimeLoop, TickStats
from twin.session.machine_io import check_safe, safe_stop
from twin.session.setup import axis_models, measured_position

__all__ = ["Recording", "run_excitation"]


@dataclass
class Recording:
    """What one run of the excitation recorded, one entry per tick (and per accelerometer
    sample).

    Attributes
    ----------
    slot : ndarray of int
        The tick's slot (its index in the excitation's time line; a paced loop may skip one).
    time : ndarray
        The driver's time stamp of each tick's read (s).
    dac : ndarray
        Volts written to the measured axis' DAC.
    regulator : ndarray
        The regulator's share of them (V): what the position loop fed back.
    position : ndarray
        The measured axis' encoder position (m).
    tacho : ndarray
        Its tacho as read (V).
    accel_clock : ndarray
        Per tick, when the read was taken on the accelerometer's clock (sample periods,
        ``Inputs.accel_clock``; nan: no accelerometer): it places the tick on the sensor's
        clock where the driver's clock is another (real I/O).
    accel_sequence : ndarray of int
        The accelerometer's sample numbers (empty without one).
    accel : ndarray
        Those samples' channel of the measured axis (m/s²).
    excitation : ndarray
        The excitation's volts by slot (what each slot was to add).
    lost : int
        Accelerometer samples the FIFO dropped.
    stats : TickStats or None
        The paced loop's deadline report (None: lock-step).
    """

    slot: np.ndarray
    time: np.ndarray
    dac: np.ndarray
    regulator: np.ndarray
    position: np.ndarray
    tacho: np.ndarray
    accel_clock: np.ndarray
    accel_sequence: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    accel: np.ndarray = field(default_factory=lambda: np.zeros(0))
    excitation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lost: int = 0
    stats: TickStats | None = None


class _Runner:
    def __init__(self, driver: MachineIO, base: MachineConfig, belief: MachineConfig,
                 axis: str, loop: str, volts: np.ndarray, offset: np.ndarray,
                 window: Sequence[tuple[float, float]], accelerometer: bool):
        self.driver, self.base, self.loop = driver, base, loop
        self.k = AXES.index(axis)
        self.period = base.controller.period
        gains = loop_gains(base.controller, [base.axes[a] for a in AXES],
                           axis_models(belief), base.controller.regulator.dcu_order)
        self.regulator = PositionRegulator(gains, self.period)
        self.encoder = EncoderUnwrapper([base.axes[a].counts_per_metre for a in AXES],
                                        bits=[base.axes[a].encoder.bits for a in AXES])
        self.volts = volts
        self.offset = offset
        self.volts_per_speed = belief.axes[axis].volts_per_speed
        self.vel = np.zeros(2)
        self.window = list(window)
        self.accelerometer = accelerometer
        self.out = Outputs()
        self.held = np.zeros(2)
        self.ref = np.zeros(2)
        self.zero = np.zeros(2)
        self.rows: list[tuple] = []
        self.accel: list[np.ndarray] = []
        self.accel_seq: list[np.ndarray] = []
        self.lost = 0

    def start(self) -> None:
        counts = self.driver.read().encoder_counts
        here = measured_position(counts, self.base)
        self.encoder.reset(counts, position=here)
        self.ref[:] = here
        self.regulator.reset(here)

    def tick(self, slot: int, t: float) -> bool:
        if slot >= len(self.volts):
            return False
        inputs = self.driver.read()
        pos = self.encoder.update(inputs.encoder_counts)
        self._check(inputs, pos, slot)
        self.vel[self.k] = self.offset[slot]
        clock = inputs.accel_clock if self.accelerometer else math.nan
        if self.accelerometer and inputs.accel_count:
            n = inputs.accel_count
            self.accel.append(inputs.accel_samples[:n, self.k].copy())
            self.accel_seq.append(inputs.accel_sequence + np.arange(n, dtype=np.int64))
            if inputs.accel_overrun:
                self.lost += 1
        self.ref = self.ref + self.vel * self.period   # the offset's ramp, per slot
        if self.rows:
            self.ref += self.vel * self.period * (slot - self.rows[-1][0] - 1)
        status = self.regulator.update(self.ref, self.vel, self.zero, self.zero, pos)
        if status >= RegulatorStatus.FOLLOWING_ERROR:
            raise ExperimentAborted(
                f"following error beyond the limit at slot {slot} (x "
                f"{1e6 * self.regulator.error[0]:.1f} µm, y "
                f"{1e6 * self.regulator.error[1]:.1f} µm)")
        dac = self.held.copy()          # compute ahead, as the controller does
        self.held[:] = self.regulator.output
        fed_back = dac[self.k]
        if self.loop == "position":
            dac[self.k] += self.volts[slot]
        else:
            dac[self.k] = self.offset[slot] * self.volts_per_speed + self.volts[slot]
            fed_back = 0.0
        self.out.dac_volts[:] = dac
        self.out.enable = True
        self.driver.write(self.out)
        self.rows.append((slot, inputs.time, dac[self.k], fed_back, pos[self.k],
                          inputs.tacho_volts[self.k], clock))
        return True

    def _check(self, inputs, pos, slot: int) -> None:
        check_safe(inputs, pos, self.window,
                   f"at x {1e3 * pos[0]:.3f} mm, y {1e3 * pos[1]:.3f} mm (tick {slot})",
                   room="the measurement")

    def stop(self) -> None:
        """Safe stop: outputs zero, drives disabled."""
        safe_stop(self.driver, self.out)

    def recording(self, stats: TickStats | None) -> Recording:
        table = np.array(self.rows, dtype=float).reshape(-1, 7)
        seq = (np.concatenate(self.accel_seq) if self.accel_seq
               else np.zeros(0, dtype=np.int64))
        acc = np.concatenate(self.accel) if self.accel else np.zeros(0)
        return Recording(table[:, 0].astype(np.int64), table[:, 1], table[:, 2],
                         table[:, 3], table[:, 4], table[:, 5], table[:, 6], seq, acc,
                         self.volts, self.lost, stats)


def run_excitation(driver: MachineIO, base: MachineConfig, belief: MachineConfig, *,
                   axis: str, loop: str, volts: np.ndarray, offset: float | np.ndarray,
                   window: Sequence[tuple[float, float]], accelerometer: bool,
                   paced: bool) -> Recording:
    """Run the excitation ``volts`` (V, one value per controller period) on ``axis`` about
    the table speed ``offset`` (m/s; one for the run or one per controller period), within
    ``window`` (each axis' (lowest, highest)
    position, m), and return the record; the machine is stopped (outputs zero, drives
    disabled) however it ends.

    Raises
    ------
    ExperimentAborted
        A safety stop (see the module docstring).
    """
    volts = np.asarray(volts, dtype=float)
    runner = _Runner(driver, base, belief, axis, loop, volts,
                     np.broadcast_to(np.asarray(offset, dtype=float), volts.shape), window,
                     accelerometer)
    runner.start()
    runner.stop()  # a clean enable edge: the drives start from their reset state
    stats = None
    try:
        if paced:
            stats = RealTimeLoop(base.controller.period).run(runner.tick)
        else:
            slot = 0
            while runner.tick(slot, slot * base.controller.period):
                slot += 1
    finally:
        runner.stop()
    return runner.recording(stats)
