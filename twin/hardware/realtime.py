"""Real-time pacing of a cyclic task with absolute deadlines, and the deadline report.

Seed 000 chose its 200 Hz position-loop rate from a table of timer statistics: ticks due
against ticks that actually fired. ``RealTimeLoop`` reports the same figures for any driver:
ticks due, ticks on time, late ticks, skipped ticks and the start jitter (p50/p99/max).

Deadlines are absolute (t0 + k·T), so lateness does not accumulate. A tick that starts more
than a whole period late skips the slots it overran (they count as due, not as on time): a
controller must never run two periods back to back on stale inputs.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass

import numpy as np

from twin.errors import DeadlineFault

__all__ = ["DeadlinePolicy", "RealTimeLoop", "TickStats", "fifo_priority",
           "set_fifo_priority"]


@dataclass(frozen=True)
class TickStats:
    """Deadline report of a paced (or lock-step) run.

    Attributes
    ----------
    period : float
        Nominal period (s).
    due : int
        Ticks that were due in the elapsed time.
    on_time : int
        Ticks that started within ``tolerance`` of their deadline.
    late : int
        Ticks that ran but started later than ``tolerance``.
    skipped : int
        Due ticks that never ran because an earlier tick overran its slot.
    jitter_p50_us, jitter_p99_us, jitter_max_us : float
        Start lateness of the ticks that ran (µs).
    tolerance : float
        Lateness still counted as on time (s).
    paced : bool
        False for a lock-step simulation (no wall-clock deadlines at all).
    """

    period: float
    due: int
    on_time: int
    late: int
    skipped: int
    jitter_p50_us: float
    jitter_p99_us: float
    jitter_max_us: float
    tolerance: float
    paced: bool = True

    @property
    def on_time_ratio(self) -> float:
        """Fraction of due ticks that started on time."""
        return self.on_time / self.due if self.due else 1.0

    def to_dict(self) -> dict:
        """Plain dict for JSON reports."""
        d = asdict(self)
        d["on_time_ratio"] = self.on_time_ratio
        return d

    @classmethod
    def lockstep(cls, period: float, ticks: int) -> TickStats:
        """Report of a lock-step run: every tick ran at its simulated instant."""
        return cls(period, ticks, ticks, 0, 0, 0.0, 0.0, 0.0, 0.0, paced=False)

    @classmethod
    def from_lateness(cls, period: float, lateness: np.ndarray, skipped: int, *,
                      tolerance: float) -> TickStats:
        """Summarise the start lateness (s) of the ticks that ran."""
        lat = np.asarray(lateness, dtype=np.float64)
        ran = len(lat)
        on_time = int(np.count_nonzero(lat <= tolerance))
        if ran:
            p50, p99, pmax = (float(v) * 1e6 for v in np.percentile(lat, [50, 99, 100]))
        else:
            p50 = p99 = pmax = 0.0
        return cls(period, ran + skipped, on_time, ran - on_time, skipped, p50, p99, pmax,
                   tolerance)


class DeadlinePolicy:
    """The machine's policy on missed deadlines (``controller.deadlines``), applied slot by
    slot: a FAULT (``DeadlineFault``) when more than ``max_skipped_in_a_row`` periods are
    lost in a row, or when the on-time share of the last ``window`` slots falls below
    ``min_on_time``; a warning (``on_warning``, at most once per window) when it falls below
    ``warn_on_time`` or when periods are lost. Lost slots count as late. Warnings start once
    a tenth of a window has passed, the share's FAULT once a whole window has (the first
    ticks of a run settle the caches), so a slipping loop is warned about before it stops.
    """

    def __init__(self, period: float, *, max_skipped_in_a_row: int = 4, window: float = 1.0,
                 min_on_time: float = 0.9, warn_on_time: float = 0.97,
                 on_warning: Callable[[str], None] | None = None):
        self.period = period
        self.max_skipped = max_skipped_in_a_row
        self.slots = max(1, round(window / period))
        self.min_on_time, self.warn_on_time = min_on_time, warn_on_time
        self.on_warning = on_warning
        self._recent: deque[bool] = deque(maxlen=self.slots)
        self._on_time = 0
        self._seen = 0
        self._warned_at = -self.slots

    @classmethod
    def from_config(cls, cfg, period: float, on_warning: Callable[[str], None] | None = None
                    ) -> DeadlinePolicy:
        """From a ``DeadlineConfig``."""
        return cls(period, max_skipped_in_a_row=cfg.max_skipped_in_a_row, window=cfg.window,
                   min_on_time=cfg.min_on_time, warn_on_time=cfg.warn_on_time,
                   on_warning=on_warning)

    def _push(self, on_time: bool) -> None:
        if len(self._recent) == self.slots:
            self._on_time -= self._recent[0]
        self._recent.append(on_time)
        self._on_time += on_time
        self._seen += 1

    def observe(self, on_time: bool, skipped: int) -> None:
        """One tick ran (``on_time`` or late), then ``skipped`` slots were lost.

        Raises
        ------
        DeadlineFault
            Naming the rule that was broken and the figures."""
        self._push(on_time)
        for _ in range(min(skipped, self.slots)):
            self._push(False)
        if skipped > self.max_skipped:
            raise DeadlineFault(
                f"deadline policy: {skipped} periods of {self.period * 1e3:g} ms lost in a "
                f"row, more than controller.deadlines.max_skipped_in_a_row = "
                f"{self.max_skipped}")
        if self._seen < max(self.slots // 10, 1):
            return
        share = self._on_time / len(self._recent)
        if share < self.min_on_time and self._seen >= self.slots:
            raise DeadlineFault(
                f"deadline policy: {100 * share:.1f} % of the last {self.slots} periods "
                f"started on time, below controller.deadlines.min_on_time = "
                f"{100 * self.min_on_time:g} %")
        if skipped:
            self._warn(f"deadlines: {skipped} period{'s' if skipped > 1 else ''} lost in a "
                       f"row (the run stops above {self.max_skipped})")
        if share < self.warn_on_time:
            self._warn(f"deadlines: {100 * share:.1f} % of the last {len(self._recent)} "
                       f"periods on time (warning below {100 * self.warn_on_time:g} %, the "
                       f"run stops below {100 * self.min_on_time:g} %)")

    def _warn(self, message: str) -> None:
        """At most one warning per window of slots."""
        if self._seen - self._warned_at < self.slots:
            return
        self._warned_at = self._seen
        if self.on_warning is not None:
            self.on_warning(message)


class RealTimeLoop:
    """Run ``tick(k, t)`` every ``period`` seconds of wall time, with absolute deadlines.

    Parameters
    ----------
    period : float
        Tick period (s); 5e-3 (200 Hz) and 1e-3 (1 kHz) are the rates of interest.
    tolerance : float, optional
        Start lateness still counted as on time (s). Default: 10 % of the period.
    spin : float
        The last ``spin`` seconds before a deadline are busy-waited instead of slept, because
        ``time.sleep`` overshoots by tens of microseconds on a general-purpose kernel.
    clock, sleep : callables
        Injected for tests; default ``time.perf_counter`` and ``time.sleep``.
    """

    def __init__(self, period: float, *, tolerance: float | None = None, spin: float = 3e-4,
                 clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep):
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period must be a positive number of seconds, got {period}")
        self.period = period
        self.tolerance = 0.1 * period if tolerance is None else tolerance
        self.spin = spin
        self._clock = clock
        self._sleep = sleep
        self._stop = False
        self._lateness: list[float] = []
        self._skipped = 0
        self.start = 0.0
        """float: clock reading of tick 0's deadline in the latest ``run`` (s)."""

    def stop(self) -> None:
        """Ask the loop to end after the current tick (safe from another thread)."""
        self._stop = True

    def run(self, tick: Callable[[int, float], bool], *, max_ticks: int | None = None,
            duration: float | None = None, policy: DeadlinePolicy | None = None
            ) -> TickStats:
        """Pace ``tick`` until it returns False, ``max_ticks`` ran, or ``duration`` passed.

        ``tick(k, t)`` gets the tick index and its deadline relative to ``start`` (s); a tick
        that returns False ends the loop and is not counted. Returns the deadline report.
        With ``policy``, every tick and every lost slot is judged by it; its
        ``DeadlineFault`` ends the loop (the report stays in ``last_stats``).
        """
        period, clock = self.period, self._clock
        # the slots whose deadlines fall within ``duration``: k·period < duration
        slots = math.ceil(duration / period - 1e-9) if duration is not None else math.inf
        lateness: list[float] = []
        self._lateness = lateness
        self._skipped = skipped = 0
        k = 0
        self._stop = False
        t0 = self.start = clock()
        while not self._stop:
            if max_ticks is not None and len(lateness) >= max_ticks:
                break
            if k >= slots:
                break
            deadline = t0 + k * period
            self._wait_until(deadline)
            late = clock() - deadline
            try:
                more = tick(k, deadline - t0)
            except BaseException:
                lateness.append(late)  # it ran (and failed): a due tick
                raise
            if not more:
                break  # the slot that found nothing more to do is not a tick
            lateness.append(late)
            # Next slot: the next deadline still in the future (skip overrun slots).
            k += 1
            behind = min(int((clock() - t0) / period), slots) - k  # none past the end
            if behind > 0:
                skipped += behind
                self._skipped = skipped
                k += behind
            if policy is not None:
                policy.observe(late <= self.tolerance, max(behind, 0))
        return self.last_stats()

    def last_stats(self) -> TickStats:
        """The deadline report of the latest ``run`` so far (also after it raised)."""
        return TickStats.from_lateness(self.period, np.array(self._lateness), self._skipped,
                                       tolerance=self.tolerance)

    def _wait_until(self, deadline: float) -> None:
        clock = self._clock
        remaining = deadline - clock()
        if remaining > self.spin:
            self._sleep(remaining - self.spin)
        while clock() < deadline:
            pass


def set_fifo_priority(priority: int) -> bool:
    """Schedule the calling thread under SCHED_FIFO at ``priority`` (1 … 99; Linux, needs
    CAP_SYS_NICE), as a real-time controller would; 0 restores normal scheduling. Returns
    whether the system granted it."""
    try:
        if priority:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        else:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):
        return False
    return True


@contextlib.contextmanager
def fifo_priority(priority: int = 10) -> Iterator[bool]:
    """``set_fifo_priority`` while inside; yields whether it was granted (priority 0: no
    change, yields False)."""
    granted = priority > 0 and set_fifo_priority(priority)
    try:
        yield granted
    finally:
        if granted:
            set_fifo_priority(0)
