"""Test signals: a raw step or ramp of one axis as the position reference (seed 000's rig
had a mode for them), in place of the planned program.

``TestSignal`` has the interpolator's interface as the controller uses it (``reference``,
``update``, ``stop``), so ``Controller.test_signal`` runs it through the controller's own
tick: the same encoder, safety checks, regulator with its feed-forward and DCU, compute
ahead and record as a program. The reference jumps (a step) or starts at full speed (a
ramp), which the planner would never produce: that is the point of the experiment.

Typical use
-----------
>>> sig = TestSignal([0.1, 0.2], axis=0, kind="ramp", amplitude=0.01, period=0.005)
>>> for _ in range(3):
...     _ = sig.update()
>>> sig.reference.position.round(9).tolist(), sig.reference.velocity.tolist()
([0.1001, 0.2], [0.01, 0.0])
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from twin.controller.interpolator import InterpolatorStatus, Reference
from twin.errors import ConfigError

__all__ = ["SIGNALS", "TestSignal"]

SIGNALS = ("step", "ramp")
"""The test signals: a step of ``amplitude`` (m) at the first tick, or a ramp at
``amplitude`` (m/s) from it."""


class TestSignal:
    """A step or ramp of one axis from ``start`` (m); the other axis holds its position.

    The n-th ``update`` (n = 0, 1, …) gives the reference at t = n·period: a step is
    already there at t = 0, a ramp has moved ``amplitude``·t. It runs until ``stop()``.

    Parameters
    ----------
    start : sequence of 2 float
        The reference before the signal (m).
    axis : int
        0 (x) or 1 (y).
    kind : {"step", "ramp"}
    amplitude : float
        Step height (m) or ramp speed (m/s), non-zero.
    period : float
        Controller period (s).
    """

    __test__ = False  # not a pytest test class, whatever its name

    def __init__(self, start: Sequence[float], *, axis: int, kind: str, amplitude: float,
                 period: float):
        if kind not in SIGNALS:
            raise ConfigError("kind", f"must be one of {SIGNALS}, got {kind!r}")
        if axis not in (0, 1):
            raise ConfigError("axis", f"must be 0 (x) or 1 (y), got {axis!r}")
        if not (isinstance(amplitude, int | float) and math.isfinite(amplitude)
                and amplitude != 0.0):
            raise ConfigError("amplitude", f"must be a non-zero number, got {amplitude!r}")
        self.start = [float(p) for p in start]
        self.axis, self.kind, self.amplitude, self.period = axis, kind, float(amplitude), period
        self.reference = Reference()
        self.reference.position[:] = self.start
        self.on_event: Callable[[float, Any], None] | None = None
        self.error = None
        self._cur = None          # no planned block: the controller's Python path runs it
        self._ticks = 0
        self._stopped = False

    def update(self) -> InterpolatorStatus:
        """The next tick's reference."""
        ref = self.reference
        if self._stopped:
            ref.velocity[:] = 0.0
            ref.status = InterpolatorStatus.FINISHED
            return ref.status
        t = self._ticks * self.period
        k = self.axis
        if self.kind == "step":
            ref.position[k] = self.start[k] + self.amplitude
        else:
            ref.position[k] = self.start[k] + self.amplitude * t
            ref.velocity[k] = self.amplitude
        ref.time = t
        self._ticks += 1
        ref.status = InterpolatorStatus.WORKING
        return ref.status

    def stop(self) -> None:
        """End the signal: the reference stays where it is."""
        self._stopped = True
