"""The one tick loop: read the machine, tick the controller, write its outputs.

Every user of the controller runs it through ``TickLoop``: ``twin run`` (lock-step on the
twin, or paced on real I/O), the tuning runs and environments, ``twin experiment`` and the
identification's jogs. What differs between them is only what happens around a tick:

- ``after_tick()`` after every tick (a run appends the twin's truth row);
- ``checkpoint()`` every ``every`` ticks (a run checks stop signals, sends telemetry);
- ``next_command()`` when the controller is at rest (manual mode starts its next command;
  False ends the loop).

The controller's read-ahead (the next block's profile, the streamed planner's next chunk)
runs after the outputs are written (``Controller.read_ahead``), not inside the tick: the
time from reading the machine to writing it is the tick alone.

Lock-step (``run``) ticks as fast as the machine answers; paced (``run_paced``) ticks once
per period of wall time under ``RealTimeLoop``'s absolute deadlines and the machine's
deadline policy. Neither collects cyclic garbage while it runs: the loop makes no reference
cycles, only short-lived tuples, and a collection of a large heap costs several periods.
"""

from __future__ import annotations

import gc
from collections.abc import Callable

from twin.controller.controller import Controller
from twin.controller.io import MachineIO
from twin.hardware.realtime import DeadlinePolicy, RealTimeLoop, TickStats, fifo_priority

__all__ = ["TickLoop"]


class TickLoop:
    """Tick ``controller`` against ``driver`` until it is done (see the module docstring).

    Parameters
    ----------
    controller : Controller
    driver : MachineIO
    after_tick : callable(), optional
        Called after every tick.
    every : int
        Ticks between checkpoints (0: none).
    checkpoint : callable(), optional
        Called every ``every`` ticks; it may raise to end the loop (a stop signal).
    next_command : callable() -> bool, optional
        Called when the controller is done: True if it started another motion, False to
        end the loop. Default: end the loop.

    Attributes
    ----------
    ticks : int
        Ticks run so far.
    """

    def __init__(self, controller: Controller, driver: MachineIO, *,
                 after_tick: Callable[[], object] | None = None, every: int = 0,
                 checkpoint: Callable[[], object] | None = None,
                 next_command: Callable[[], bool] | None = None):
        self.controller, self.driver = controller, driver
        controller.read_ahead_in_tick = False   # read ahead after the write (see step)
        self.after_tick, self.checkpoint = after_tick, checkpoint
        self.every = every if checkpoint is not None and every > 0 else 0
        self.next_command = next_command or (lambda: False)
        self.ticks = 0
        self.t = 0.0
        """Paced: the deadline of the tick running, from the loop's start (s)."""
        self.realtime: RealTimeLoop | None = None
        """Paced: the ``RealTimeLoop`` (its ``start`` is the wall time of slot 0)."""
        self.stats: TickStats | None = None
        self.rt_granted = False

    def step(self, _k: int = 0, _t: float = 0.0) -> bool:
        """One tick; False (nothing done) when the controller is done and no command
        follows. Its signature is ``RealTimeLoop``'s."""
        ctrl = self.controller
        if ctrl.done and not self.next_command():
            return False
        self.t = _t
        self.driver.write(ctrl.tick(self.driver.read()))
        ctrl.read_ahead()
        if self.after_tick is not None:
            self.after_tick()
        self.ticks += 1
        if self.every and self.ticks % self.every == 0:
            self.checkpoint()  # type: ignore[misc]
        return True

    def run(self, max_ticks: int | float) -> int:
        """Lock-step: tick until done or ``max_ticks`` ticks in all; returns the ticks run
        by this call."""
        first, step = self.ticks, self.step
        paused = gc.isenabled()
        gc.disable()
        try:
            while self.ticks < max_ticks and step():
                pass
        finally:
            if paused:
                gc.enable()
        return self.ticks - first

    def run_paced(self, period: float, *, max_ticks: int | None = None,
                  policy: DeadlinePolicy | None = None, rt_priority: int = 0) -> TickStats:
        """Real I/O: one tick per ``period`` of wall time (absolute deadlines), under
        SCHED_FIFO at ``rt_priority`` where the OS grants it (0: normal). Returns the
        deadline report; it is also ``stats`` (with ``rt_granted``) when a
        ``DeadlineFault`` or a stop ends the loop."""
        loop = self.realtime = RealTimeLoop(period)
        paused = gc.isenabled()
        gc.collect()     # one collection before, none inside (see the module docstring)
        gc.disable()
        try:
            with fifo_priority(rt_priority) as self.rt_granted:
                loop.run(self.step, max_ticks=max_ticks, policy=policy)
        finally:
            if paused:
                gc.enable()
            self.stats = loop.last_stats()
        return self.stats
