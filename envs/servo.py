"""``XYTable-Servo-v0``: residual control of the position loop, one step per control period."""

from __future__ import annotations

import math
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from envs.programs import PROGRAMS, tuning_program
from envs.randomize import MachineRandomizer
from twin.config import MachineConfig, load_machine
from twin.controller.controller import Controller, ControllerStatus
from twin.controller.io import Outputs
from twin.errors import ConfigError, SimulationError
from twin.session.setup import wire

__all__ = ["ServoEnv"]

_CLIP = 10.0
_DIVERGED = (ControllerStatus.INVALID_INPUT,)


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
        raise ConfigError(name, f"must be a finite number > 0, got {value!r}")
    return float(value)


class ServoEnv(gym.Env):
    """Add a learned correction to the position regulator's output while a program runs.

    The twin runs a program under the full controller (planner, interpolator, regulator
    with the machine's gains and DCU order); every control period the agent adds a
    correction to each axis' regulator output before the DAC — residual control, for
    studies of learned feed-forward. The zero action reproduces the plain controller.

    ## Action Space

    ``Box(-1, 1, (2,), float32)``: the correction of the x and y speed references, in units
    of ``max_correction`` (V). NaN or inf raises ``ValueError``; finite values are clipped.

    ## Observation Space

    ``Box(-10, 10, (10,), float32)``, every entry clipped to ±10:

    | Num | Observation                         | Unit                              |
    |-----|-------------------------------------|-----------------------------------|
    | 0-1 | following error x, y                | ``error_scale`` (m)               |
    | 2-3 | reference velocity x, y             | contour ``max_velocity`` (m/s)    |
    | 4-5 | reference acceleration x, y         | contour ``max_acceleration``      |
    | 6-7 | reference jerk x, y                 | contour ``max_jerk`` (m/s³)       |
    | 8-9 | regulator output x, y               | DAC full scale (V)                |

    ## Rewards

    ``reward = -(tracking + effort + failure)``, each in ``info["terms"]``:
    ``tracking = w_tracking · mean_axes((e/error_scale)²)`` after the step,
    ``effort = w_effort · mean_axes(action²)``, ``failure = penalty`` when the step
    diverged or tripped, else 0.

    ## Starting State

    The table at the home keyframe, the program planned from there (a random machine
    variant with ``randomize=True``); the first period has been ticked.

    ## Episode End

    Terminated when the program has finished (``FINISHED``), or on divergence
    (``info["diverged"]``) or a controller trip (``info["tripped"]``) with ``-penalty``.
    Truncation belongs to the ``TimeLimit`` wrapper (20 000 periods for the registered id).

    ## Arguments

    | Argument       | Default      | Description                                    |
    |----------------|--------------|------------------------------------------------|
    | machine        | "tomsk_xy"   | preset name, TOML path or ``MachineConfig``    |
    | program        | "tiny"       | program name (``envs.programs.PROGRAMS``)      |
    | randomize      | False        | draw a machine variant on every reset          |
    | max_correction | 0.5          | correction at action ±1 (V)                    |
    | error_scale    | 100e-6       | following error that counts as 1 (m)           |
    | w_tracking     | 1.0          | weight of the tracking term                    |
    | w_effort       | 0.01         | weight of the effort term                      |
    | penalty        | 100.0        | reward lost on divergence or trip              |
    | dcu_order      | None         | DCU order of the controller (machine's if None)|

    ## Version History

    * v0: initial version.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, *, machine: str | MachineConfig = "tomsk_xy", program: str = "tiny",
                 randomize: bool = False, max_correction: float = 0.5,
                 error_scale: float = 100e-6, w_tracking: float = 1.0, w_effort: float = 0.01,
                 penalty: float = 100.0, dcu_order: int | None = None,
                 render_mode: str | None = None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError("render_mode", f"must be None or one of "
                              f"{self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self._base = machine if isinstance(machine, MachineConfig) else load_machine(machine)
        if program not in PROGRAMS:
            raise ConfigError("program", f"unknown program {program!r}; valid: "
                              f"{', '.join(PROGRAMS)}")
        self._program = program
        self._randomizer = MachineRandomizer(self._base) if randomize else None
        self.max_correction = _positive("max_correction", max_correction)
        self.error_scale = _positive("error_scale", error_scale)
        self.w_tracking = float(w_tracking)
        self.w_effort = float(w_effort)
        self.penalty = _positive("penalty", penalty)
        self._dcu_order = dcu_order
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.observation_space = gym.spaces.Box(-_CLIP, _CLIP, (10,), dtype=np.float32)
        self._out = Outputs()
        self._ctrl: Controller | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        cfg = self._randomizer.sample(self.np_random) if self._randomizer else self._base
        wired = wire(cfg, lambda start: tuning_program(self._program, cfg, start),
                     dcu_order=self._dcu_order)
        self._ctrl, self._driver = wired.controller, wired.driver
        lim = cfg.controller.limits
        self._scale = np.array([self.error_scale] * 2 + [lim.max_velocity] * 2
                               + [lim.max_acceleration] * 2 + [lim.max_jerk] * 2
                               + list(np.broadcast_to(self._ctrl.gains.output_limit, 2)))
        self._pending = self._ctrl.tick(self._driver.read())
        return self._observation(), {"machine": cfg.name, "program": self._program}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self._ctrl is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (2,):
            raise ValueError(f"action must have 2 entries, got shape {np.shape(action)}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite numbers in [-1, 1], got {a.tolist()}")
        a = np.clip(a, -1.0, 1.0)
        ctrl, out = self._ctrl, self._out
        out.enable = self._pending.enable
        out.dac_volts[:] = self._pending.dac_volts
        if out.enable:
            out.dac_volts += self.max_correction * a
        diverged = False
        try:
            self._driver.write(out)
            self._pending = ctrl.tick(self._driver.read())
        except SimulationError:
            diverged = True
        status = ctrl.status
        diverged = diverged or status in _DIVERGED
        tripped = not diverged and status > ControllerStatus.FINISHED
        failed = diverged or tripped
        err = ctrl.regulator.error / self.error_scale
        terms = {"tracking": 0.0 if failed else self.w_tracking * float(np.mean(err * err)),
                 "effort": self.w_effort * float(np.mean(a * a)),
                 "failure": self.penalty if failed else 0.0}
        done = failed or status == ControllerStatus.FINISHED
        info = {"terms": terms, "diverged": diverged, "tripped": tripped,
                "status": "DIVERGED" if diverged else status.name,
                "following_error": ctrl.regulator.error.copy()}
        return self._observation(), -math.fsum(terms.values()), done, False, info

    def render(self) -> np.ndarray | None:
        """``render_mode="rgb_array"``: the episode so far, (H, W, 3) uint8: each axis'
        following error (µm) against time, and the table's path with the programmed one;
        None without a render mode."""
        if self.render_mode is None or self._ctrl is None:
            return None
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        rec = self._ctrl.record.as_arrays()
        fig = Figure(figsize=(6.4, 3.6), dpi=100)
        canvas = FigureCanvasAgg(fig)
        left, right = fig.subplots(1, 2)
        if len(rec["t"]):
            for k, axis in enumerate("xy"):
                left.plot(rec["t"], rec["following_error"][:, k] * 1e6, label=axis)
            right.plot(rec["ref_position"][:, 0] * 1e3, rec["ref_position"][:, 1] * 1e3,
                       "k--", lw=0.8, label="reference")
            right.plot(rec["position"][:, 0] * 1e3, rec["position"][:, 1] * 1e3, lw=1.0,
                       label="table")
        left.set(xlabel="t (s)", ylabel="following error (µm)")
        left.legend(fontsize=7)
        right.set(xlabel="x (mm)", ylabel="y (mm)", aspect="equal")
        right.legend(fontsize=7)
        fig.suptitle(f"{self._program}: {self._ctrl.status.name}", fontsize=9)
        fig.tight_layout()
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()

    def _observation(self) -> np.ndarray:
        ctrl = self._ctrl
        ref = ctrl.interpolator.reference
        raw = np.concatenate([ctrl.regulator.error, ref.velocity, ref.acceleration, ref.jerk,
                              ctrl.regulator.output])
        obs = np.nan_to_num(raw / self._scale, nan=_CLIP, posinf=_CLIP, neginf=-_CLIP)
        return np.clip(obs, -_CLIP, _CLIP).astype(np.float32)
