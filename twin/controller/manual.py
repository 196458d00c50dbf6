"""The controller's manual mode (issue 4) and test signals: commands that start a motion
from rest — another program, a jog, a home search, a raw step or ramp — as a mixin of
`twin.controller.controller.Controller` (its planner, interpolator and regulator).

``home(axis)`` moves toward the home switch until it closes, brakes, and declares the
latched position to be the configured home position; the cyclic path (``_progress``) calls
``_finish_homing`` when the braking is done.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

from twin.config import AXES
from twin.controller.geometry import Line
from twin.controller.planner import MotionBlock
from twin.controller.signals import TestSignal
from twin.controller.status import ControllerStatus
from twin.errors import ConfigError, PlanningError

__all__ = ["ManualCommands"]


class ManualCommands:
    """Commands of a controller at rest (mixed into ``Controller``)."""

    # provided by Controller
    status: ControllerStatus
    position_reference: tuple[float, float]

    def _start_motion(self, blocks: Iterable[Any], status: ControllerStatus,
                      source: Callable[[tuple[float, float]], Any] | None = None) -> None:
        """Start following ``blocks`` from the present reference (or the reference source
        ``source(here)`` makes, a test signal) at rest."""
        if self.status not in (ControllerStatus.IDLE, ControllerStatus.FINISHED):
            raise PlanningError(f"cannot start a motion while {self.status.name}; "
                                "wait for FINISHED or call reset()")
        here = self.position_reference
        self._rest_at(here, self._interpolator(blocks, here) if source is None
                      else source(here))
        self.status = status

    def run_program(self, program: Iterable[Any]) -> None:
        """Start another program from rest (checked against the work zone first)."""
        self._start_motion(self._blocks(program, self.position_reference),
                           ControllerStatus.RUNNING)

    def jog(self, target: Sequence[float], *, feed: float | None = None) -> None:
        """Move in a straight line to ``target`` (m) at ``feed`` (m/s; default the contour
        ``max_velocity``). Raises ``PlanningError`` if the target leaves the work zone or
        the controller is not at rest."""
        line = Line(self.position_reference, target)
        feed = self.settings.limits.max_velocity if feed is None else feed
        block = MotionBlock(line, feed)
        self.planner.check([block])
        self._start_motion(self.planner.plan([block]), ControllerStatus.RUNNING)

    def test_signal(self, axis: str, kind: str, amplitude: float) -> None:
        """Follow a raw step (``amplitude`` m) or ramp (``amplitude`` m/s) of ``axis`` from
        the present reference, instead of a planned program (``signals.TestSignal``), until
        ``interpolator.stop()``; the other axis holds. The soft limits are not checked:
        the caller keeps the signal inside the travel (the limit switches still trip)."""
        if axis not in AXES:
            raise ConfigError("axis", f"must be one of {AXES}, got {axis!r}")
        self._start_motion((), ControllerStatus.RUNNING, lambda here: TestSignal(
            here, axis=AXES.index(axis), kind=kind, amplitude=amplitude, period=self.period))

    def home(self, axis: str, *, feed: float | None = None, direction: int | None = None
             ) -> None:
        """Search the home switch of ``axis``: move toward it until ``inputs.home`` closes,
        brake, and declare the latched position to be ``switches.home``.

        Parameters
        ----------
        axis : {"x", "y"}
        feed : float, optional
            Search speed (m/s); default a quarter of the axis' max velocity.
        direction : {-1, +1}, optional
            Default toward the nearer end of travel from the home switch.
        """
        if axis not in AXES:
            raise ConfigError("axis", f"must be one of {AXES}, got {axis!r}")
        k = AXES.index(axis)
        cfg = self.axes[k]
        sw, travel = cfg.switches, cfg.mechanics.travel
        if direction is None:
            direction = -1 if sw.home - travel[0] <= travel[1] - sw.home else 1
        if direction not in (-1, 1):
            raise ConfigError("direction", f"must be -1 or +1, got {direction!r}")
        here = self.position_reference
        target = list(here)
        target[k] += direction * (travel[1] - travel[0])
        feed = 0.25 * cfg.limits.max_velocity if feed is None else feed
        blocks = self._free_planner.plan([MotionBlock(Line(here, target), feed)])
        self._start_motion(blocks, ControllerStatus.HOMING)
        self._homing = (k, float(sw.home))
        self._home_latch = None

    def _finish_homing(self) -> None:
        """After the braking: shift the coordinates so the latch is at the home position."""
        k, home = self._homing  # type: ignore[misc]
        offset = [0.0, 0.0]
        offset[k] = home - self._home_latch  # type: ignore[operator]
        self.encoder.rebase(offset)
        here = list(self.position_reference)
        here[k] += offset[k]
        self._rest_at(here)
        self._homing = self._home_latch = None
