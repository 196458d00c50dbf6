"""``SimDriver``: the twin behind the ``MachineIO`` port, in lock-step.

``read()`` samples the plant's sensors; ``write()`` applies the outputs and advances the plant
by exactly one controller period, so simulated time runs as fast as the machine allows and a
run is deterministic. The controller cannot tell this driver from a real I/O module.
"""

from __future__ import annotations

import numpy as np

from twin.config import TimingConfig
from twin.controller.io import Inputs, Outputs
from twin.hardware.timing import TickSchedule
from twin.plant import Plant

__all__ = ["SimDriver"]


class SimDriver:
    """Lock-step driver over a ``Plant``.

    Parameters
    ----------
    plant : Plant
        The twin. Its state is whatever it is at construction (call ``plant.reset`` first).
    period : float
        Controller period (s); each ``write`` advances the plant by this much.
    drives_off : bool
        Run the controller without driving the motors (what seed 001 calls a dry run): the
        drives stay disabled whatever the controller asks. (``twin run --dry-run`` is
        another thing: the plan alone, ``twin.session.dry_run``.)
    timing : TimingConfig, optional
        When the ticks really come (``[controller.timing]``): each ``write`` then advances
        the plant to the next tick of that timer instead of by exactly one period (the
        controller does not know). Default: ideal.
    """

    def __init__(self, plant: Plant, period: float, *, drives_off: bool = False,
                 timing: TimingConfig | None = None):
        if not period > 0:
            raise ValueError(f"period must be > 0 s, got {period}")
        self.plant = plant
        self.period = period
        self.drives_off = drives_off
        self._zero = np.zeros(2)
        self._inputs = Inputs()
        self._enabled: bool | None = None  # unknown: the first write sets it
        self.schedule = None if timing is None or timing.ideal else TickSchedule(
            period, timing, plant.drive_dt)
        """TickSchedule or None: the simulated timer (None: every tick on time)."""
        self._now = plant.time

    def read(self) -> Inputs:
        """Sample encoders, tachos and switches now (one ``Inputs`` object, reused: a
        controller reads it within its tick and keeps nothing)."""
        self.plant.read_into(self._inputs)
        return self._inputs

    def write(self, outputs: Outputs) -> None:
        """Apply the outputs and advance the plant one period."""
        enable = bool(outputs.enable) and not self.drives_off
        if enable != self._enabled:
            self.plant.enable(enable)
            self._enabled = enable
        duration = self.period
        if self.schedule is not None:
            t = self.schedule.next()
            duration, self._now = t - self._now, t
        self._advance(outputs.dac_volts if enable else self._zero, duration)

    def _advance(self, dac_volts: np.ndarray, duration: float) -> None:
        """Advance the plant by ``duration`` (s) under ``dac_volts`` (V): the one place a
        subclass changes how a period is stepped (a modal hammer's blow within it,
        ``twin.session.hammer``)."""
        self.plant.step(dac_volts, duration)

    def close(self) -> None:
        """Disable the drives (the plant keeps its state for inspection)."""
        self.plant.enable(False)
        self._enabled = False
