"""When a non-real-time PC's timer really fires: a simulated tick schedule for lock-step runs.

Seed 000's rig ran its position loop from a Windows timer, and measured it (ticks that fired
in 1 s at periods 100/50/10/5 ms): a plain software timer 9/15/62/63, a multimedia timer
10/20/99/199. :class:`TickSchedule` reproduces such a timer for ``SimDriver``: the instants
at which the controller's ticks come, so a lock-step run on the twin shows what late and
lost ticks do to the contour (``[controller.timing]``, ``TimingConfig``). The controller
never knows: it assumes one period between ticks.

The model, per tick:

1. due: one period after the last *due* instant (``rearm = "absolute"``, a periodic timer;
   slots that passed while a tick was late are lost) or after the last tick *taken*
   (``"relative"``, a timer re-armed by its handler, as ``SetTimer``/``WM_TIMER`` is);
2. lost with probability ``skip_probability`` (the slot passes without a tick);
3. fired at the first multiple of ``granularity`` at or after that instant (the OS clock
   tick: 15.625 ms, 64 Hz, for a default Windows of the rig's time);
4. late by U(0, ``late_max``] with probability ``late_probability``;
5. rounded to the twin's drive interval, the resolution at which the plant can be stepped
   (and never less than one interval after the last tick).

Seed 000's plain software timer is ``granularity = 0.015625, rearm = "relative"``: 9.1, 16,
64, 64 ticks per second at 100, 50, 10, 5 ms, against the measured 9, 15, 62, 63
(``tests/hardware/test_timing.py``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from twin.config import TimingConfig
from twin.hardware.realtime import TickStats

__all__ = ["SEED000_SOFTWARE_TIMER", "TickSchedule"]

SEED000_SOFTWARE_TIMER = TimingConfig(granularity=0.015625, rearm="relative")
"""Seed 000's plain software timer: a relative timer on the OS's 64 Hz clock tick."""


class TickSchedule:
    """The instants (s) of a controller's ticks under a ``TimingConfig``.

    Parameters
    ----------
    period : float
        The controller's nominal period (s).
    timing : TimingConfig
        The timer model.
    resolution : float
        The finest step of the simulated plant (s): tick instants are rounded to it.

    Examples
    --------
    >>> from twin.config import TimingConfig
    >>> s = TickSchedule(0.005, TimingConfig(granularity=0.015625, rearm="relative"), 1e-3)
    >>> [round(s.next(), 3) for _ in range(4)]
    [0.016, 0.031, 0.047, 0.062]
    """

    def __init__(self, period: float, timing: TimingConfig, resolution: float):
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period must be > 0 s, got {period}")
        if not (math.isfinite(resolution) and resolution > 0):
            raise ValueError(f"resolution must be > 0 s, got {resolution}")
        self.period = period
        self.timing = timing
        self.resolution = resolution
        self._rng = np.random.default_rng(timing.seed)
        self._due = 0.0           # the slot the last tick served
        self._taken = 0.0         # when the last tick came
        self._lateness: list[float] = []
        self._skipped = 0

    @property
    def ideal(self) -> bool:
        """Every tick exactly one period after the last."""
        return self.timing.ideal

    def next(self) -> float:
        """The instant of the next tick (s); also records its lateness for :meth:`stats`."""
        tm, period = self.timing, self.period
        due = (self._due if tm.rearm == "absolute" else self._taken) + period
        while tm.skip_probability > 0.0 and self._rng.random() < tm.skip_probability:
            self._skipped += 1
            due += period
        fire = due
        if tm.granularity > 0.0:
            fire = math.ceil(fire / tm.granularity - 1e-9) * tm.granularity
        if tm.late_probability > 0.0 and self._rng.random() < tm.late_probability:
            fire += self._rng.uniform(0.0, tm.late_max) or tm.late_max
        fire = max(round(fire / self.resolution), round(self._taken / self.resolution) + 1) \
            * self.resolution
        if tm.rearm == "absolute":
            # slots that passed while this tick was late are lost, not served back to back
            lost = max(0, math.floor((fire - due) / period + 1e-9))
            self._skipped += lost
            due += lost * period
        self._lateness.append(fire - due)
        self._due, self._taken = due, fire
        return fire

    def stats(self) -> TickStats:
        """The deadline report of the ticks so far, as seed 000 counted: the slots that fell
        due in the elapsed time, the ticks that came on time (within 10 % of a period), late,
        or not at all."""
        ran = len(self._lateness)
        slots = math.floor(self._taken / self.period + 1e-9)
        skipped = max(self._skipped, slots - ran)
        stats = TickStats.from_lateness(self.period, np.array(self._lateness), skipped,
                                        tolerance=0.1 * self.period + 1e-12)
        return dataclasses.replace(stats, paced=False)
