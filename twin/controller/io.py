"""The one port between the controller and a machine: ``MachineIO``.

The controller reads ``Inputs`` (what real I/O hardware delivers) and writes ``Outputs`` once
per period. Behind the port may be the twin (``twin.hardware.sim``), a Modbus/TCP I/O module
(``twin.hardware.modbus``) or anything else that implements the three methods.

Arrays are indexed by axis in the order ``AXES = ("x", "y")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from twin.config.schema import AXES

__all__ = ["AXES", "Inputs", "MachineIO", "Outputs"]


def _zeros_i64() -> np.ndarray:
    return np.zeros(2, dtype=np.int64)


def _zeros_f() -> np.ndarray:
    return np.zeros(2)


def _false() -> np.ndarray:
    return np.zeros(2, dtype=bool)


def _no_samples() -> np.ndarray:
    return np.zeros((0, 2))


@dataclass(slots=True)
class Inputs:
    """What the machine's I/O gives the controller each period.

    Attributes
    ----------
    encoder_counts : ndarray, shape (2,), int64
        Raw hardware counter values (counts). They wrap at the counter width (32 bit on
        the reference rig: 0 … 2³²−1); the controller unwraps the differences.
    tacho_volts : ndarray, shape (2,)
        Tachogenerator voltage read by the ADC (V).
    limit_min, limit_max : ndarray, shape (2,), bool
        End limit switches (debounced), True = actuated.
    home : ndarray, shape (2,), bool
        Home (reference) switches, True = actuated.
    drive_ready : bool
        The drives report no fault.
    time : float
        Time stamp of the sample (s), the driver's clock.
    accel_samples : ndarray, shape (block, 2)
        The table accelerometer's FIFO as read this period (m/s²; channels x, y): rows
        0 … ``accel_count`` − 1 are new, oldest first; the rest is stale. Shape (0, 2)
        without an accelerometer.
    accel_count : int
        How many samples the read returned (0: none, or no accelerometer).
    accel_sequence : int
        The sensor's sample number of the first of them: sample number i was taken at i
        sample periods of the sensor's own clock, so a reader can place every sample in
        time and see a gap.
    accel_overrun : bool
        The FIFO overflowed since the last read: samples were lost.
    accel_clock : float
        When the read was taken on the sensor's clock (sample periods: the newest sample's
        number plus the elapsed fraction of the next); nan without an accelerometer.
    """

    encoder_counts: np.ndarray = field(default_factory=_zeros_i64)
    tacho_volts: np.ndarray = field(default_factory=_zeros_f)
    limit_min: np.ndarray = field(default_factory=_false)
    limit_max: np.ndarray = field(default_factory=_false)
    home: np.ndarray = field(default_factory=_false)
    drive_ready: bool = True
    time: float = 0.0
    accel_samples: np.ndarray = field(default_factory=_no_samples)
    accel_count: int = 0
    accel_sequence: int = 0
    accel_overrun: bool = False
    accel_clock: float = math.nan


@dataclass(slots=True)
class Outputs:
    """What the controller writes to the machine each period.

    Attributes
    ----------
    dac_volts : ndarray, shape (2,)
        Analog speed references to the drives (V), within the DAC range.
    enable : bool
        Drive enable. False: the drives are disabled and the references are ignored.
    """

    dac_volts: np.ndarray = field(default_factory=_zeros_f)
    enable: bool = False


@runtime_checkable
class MachineIO(Protocol):
    """A machine as the controller sees it.

    ``read`` samples the inputs at the start of a period; ``write`` applies the outputs; a
    driver that paces time itself (the lock-step twin) advances the machine by one period in
    ``write``. ``close`` leaves the machine safe: outputs zero, drives disabled.
    """

    def read(self) -> Inputs:
        """Sample the inputs now."""
        ...

    def write(self, outputs: Outputs) -> None:
        """Apply the outputs (and, for a lock-step driver, advance one period)."""
        ...

    def close(self) -> None:
        """Zero the outputs, disable the drives and release the connection."""
        ...
