"""``XYTable-GainTuning-v0``: tune the position loop of a machine, one test run per step."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from envs.evaluation import (
    METRICS,
    RunOutcome,
    Weights,
    cost_terms,
    cycle_time_limit,
    metric_scales,
    reported,
    tuning_run,
)
from envs.programs import PROGRAMS
from envs.randomize import MachineRandomizer
from envs.space import DIM, SHAPER_NAMES, TuningSettings, TuningSpace, check_action
from twin.config import MachineConfig, load_machine
from twin.config.shaper_settings import shaper_overrides
from twin.errors import ConfigError, SimulationError
from twin.session.run import axis_models

__all__ = ["GainTuningEnv", "Tuning"]

_LOG_CLIP = 5.0     # |ln(metric/scale)| shown to the agent
_ABS_CLIP = 10.0


class Tuning:
    """One machine and program under tuning: the space, the baseline and the cost.

    ``Tuning(cfg, program)`` runs the analytic baseline once; ``evaluate(action)`` runs
    the program with the decoded settings and returns the outcome with its cost terms.
    The tuning jobs (``tuning``) use this object directly; the env wraps it.

    Parameters
    ----------
    cfg : MachineConfig
        The machine.
    program : str
        Tuning program (``envs.programs.PROGRAMS``).
    weights : Weights, optional
        Cost weights; default ``Weights()``.
    penalty : float
        Cost of a failed run (1).
    max_time_factor : float
        A run may take this many times the baseline's simulated time (plus 5 s).
    baseline : RunOutcome, optional
        The analytic baseline's outcome if already known (a worker process need not run
        it again); it must come from the same machine and program.
    belief : MachineConfig, optional
        The controller's model of the machine: the analytic design, the tuning space's
        scales and the corner model come from it; the runs are on ``cfg``. Default
        ``cfg``.
    max_cycle_time_increase : float, optional
        A constraint: the cycle time may grow by at most this share (1) of the analytic
        design's; a run beyond it gets the cost term ``cycle_time_limit``
        (``envs.evaluation.cycle_time_limit``). None: no constraint (and no such term).
    """

    def __init__(self, cfg: MachineConfig, program: str = "compact", *,
                 weights: Weights | None = None, penalty: float = 50.0,
                 max_time_factor: float = 3.0, baseline: RunOutcome | None = None,
                 belief: MachineConfig | None = None,
                 max_cycle_time_increase: float | None = None):
        if max_cycle_time_increase is not None and not (
                math.isfinite(max_cycle_time_increase) and max_cycle_time_increase >= 0.0):
            raise ConfigError("max_cycle_time_increase", f"must be a share >= 0 (0.05 is "
                              f"5 %), got {max_cycle_time_increase!r}")
        self.max_cycle_time_increase = max_cycle_time_increase
        if program not in PROGRAMS:
            raise ConfigError("program", f"unknown tuning program {program!r}; valid: "
                              f"{', '.join(PROGRAMS)}")
        if not (math.isfinite(penalty) and penalty > 0.0):
            raise ConfigError("penalty", f"must be a finite number > 0, got {penalty!r}")
        self.cfg = cfg
        self.program = program
        self.weights = weights or Weights()
        self.penalty = float(penalty)
        self.belief = belief or cfg
        self.models = axis_models(self.belief)
        self.space = TuningSpace.from_machine(cfg, self.models)
        self.baseline = baseline or tuning_run(
            cfg, self.space.decode(np.zeros(self.space.dim)), models=self.models,
            program=program, model_axes=self.belief.axes)
        if self.baseline.failed:
            raise SimulationError(f"the analytic baseline fails on {cfg.name}: "
                                  f"{self.baseline.status} ({self.baseline.message})")
        self.scales = metric_scales(self.baseline)
        self.max_time = max_time_factor * self.baseline.sim_time + 5.0

    def run(self, settings: TuningSettings, *, trace: bool = False) -> RunOutcome:
        """One run with ``settings`` (``trace``: keep its errors against time,
        ``RunOutcome.trace``)."""
        return tuning_run(self.cfg, settings, models=self.models, program=self.program,
                          max_time=self.max_time, model_axes=self.belief.axes, trace=trace)

    def terms(self, outcome: RunOutcome) -> dict[str, float]:
        """Weighted cost terms (``cost_terms``) of an outcome on this machine, and the
        cycle-time constraint's (``cycle_time_limit``) when there is one."""
        terms = cost_terms(outcome, self.scales, self.weights, penalty=self.penalty)
        if self.max_cycle_time_increase is not None:
            weight = math.fsum(getattr(self.weights, m) for m in METRICS)
            terms["cycle_time_limit"] = cycle_time_limit(
                outcome, self.baseline.metrics["cycle_time"], self.max_cycle_time_increase,
                weight)
        return terms

    def evaluate(self, action: Sequence[float] | np.ndarray
                 ) -> tuple[TuningSettings, RunOutcome, dict[str, float]]:
        """Run the settings of a normalised ``action``: (settings, outcome, terms)."""
        settings = self.space.decode(action)
        outcome = self.run(settings)
        return settings, outcome, self.terms(outcome)

    @property
    def baseline_cost(self) -> float:
        """Cost of the analytic baseline (the sum of the weights of non-zero scales)."""
        return math.fsum(self.terms(self.baseline).values())

    def relative(self, outcome: RunOutcome) -> np.ndarray:
        """``ln(metric/scale)`` per metric, clipped to ±5; +5 everywhere for a failed run."""
        if outcome.failed:
            return np.full(len(METRICS), _LOG_CLIP)
        ratio = outcome.vector() / np.array([self.scales[m] for m in METRICS])
        return np.clip(np.log(np.maximum(ratio, 1e-12)), -_LOG_CLIP, _LOG_CLIP)

    def descriptor(self) -> np.ndarray:
        """What the baseline says about the machine: ``log10`` of its metrics in µm (s for
        times), clipped to ±10."""
        v = self.baseline.vector()
        unit = np.array([1e-6 if "time" not in m else 1.0 for m in METRICS])
        return np.clip(np.log10(np.maximum(v / unit, 1e-9)), -_ABS_CLIP, _ABS_CLIP)


class GainTuningEnv(gym.Env):
    """Tune the regulator gains, DCU coefficients and jerk limit of a cross table.

    One step is one complete test run of a program on the twin with the settings the
    action selects; an episode is a budget of tuning runs on one machine (the
    ``TimeLimit`` wrapper of the registered id ends it after ``max_episode_steps``).

    ## Action Space

    ``Box(-1, 1, (11,), float32)``, normalised; ``envs.space.TuningSpace`` maps it to
    physical values around the analytic design (the zero action *is* the analytic design):

    | Num | Action     | Unit       | Mapping at -1 … 0 … +1                              |
    |-----|------------|------------|-----------------------------------------------------|
    | 0   | kp_x       | V/m        | kp0/4 … kp0 … 4·kp0 (log)                           |
    | 1   | ki_x       | V/(m·s)    | 0 for ≤ 0; 1e-3 … 1 × kp0·K_v (log) above           |
    | 2-4 | a1_x…a3_x  | V/m        | α_k⁰·(1 + s_k·a), s = 0.1, 0.5, 1.0                  |
    | 5-9 | same, y    |            |                                                     |
    | 10  | max_jerk   | m/s³       | J0/4 … J0 … 4·J0 (log)                              |

    With ``shaper`` (or a machine that shapes both axes) four more, ``(15,)``:

    | 11  | sf_x       | Hz         | f0/1.5 … f0 … 1.5·f0 (log): the shaper's frequency  |
    | 12  | sz_x       | 1          | ζ0 − 0.2 … ζ0 … ζ0 + 0.2, within [0, 0.9]           |
    | 13-14 | same, y  |            |                                                     |

    NaN or inf entries raise ``ValueError``; finite ones are clipped to [-1, 1].

    ## Observation Space

    ``Box(-10, 10, (35,), float32)``:

    | Num   | Observation                                   | Unit                   |
    |-------|-----------------------------------------------|------------------------|
    | 0-7   | ln(metric / baseline scale) of the last run   | 1 (+5 for a failed run)|
    | 8-15  | log10 of the baseline's metrics               | log10 µm / log10 s     |
    | 16-26 | the settings of the last run (the action)     | 1                      |
    | 27-34 | ln(metric / scale) of the best run so far     | 1                      |

    (with a shaper: the action takes 15 entries and the observation 39).

    The metrics, in order: max and RMS coordinate error (larger axis), max and RMS
    contour error, overshoot, settling travel, cycle time, saturation time.

    ## Rewards

    ``reward = -Σ terms``; ``info["terms"]`` holds each weighted term:
    ``w_i · metric_i / scale_i`` for the eight metrics (scale: the analytic baseline's value
    on this machine and program, floored at 1 µm / 1 ms / 1 % of the cycle time) and
    ``failure`` (``penalty`` for a run that diverged or tripped, else 0). The analytic
    design scores ``-Σ w_i`` (minus the saturation weight when it never saturates).

    ``info`` also holds ``is_success`` (the run beat the analytic design: it did not fail
    and cost less), ``metrics`` in the units people read, the unit in each key
    (``max_coordinate_error_um``, ``cycle_time_s``; ``baseline_metrics`` at reset alike),
    and the run's ``settings`` (SI). The registered id's ``reward_threshold`` is -4.0: the
    analytic design's reward under the default weights when it never saturates (every
    term 1 times its weight, the saturation term 0): above it, on average, an agent beats
    the analytic design.

    ## Starting State

    ``reset`` picks the machine (the nominal one, or a random variant with
    ``randomize=True``, see ``envs.randomize``) and the program, and runs the analytic
    baseline once; the first observation describes that run, with settings 0.
    ``options={"machine": name_or_config, "program": name}`` forces either.

    ## Episode End

    Terminated when a run diverges (``info["diverged"]``) or the controller trips
    (``info["tripped"]``): the step's reward is ``-penalty``. Truncation is the
    ``TimeLimit`` wrapper's (5 runs for the registered id).

    ## Arguments

    | Argument    | Default      | Description                                         |
    |-------------|--------------|-----------------------------------------------------|
    | machine     | "tomsk_xy"   | preset name, TOML path or ``MachineConfig``         |
    | program     | "compact"    | tuning program, or a sequence to draw from          |
    | randomize   | False        | draw a machine variant on every reset               |
    | weights     | ``Weights()``| cost weights per metric                             |
    | penalty     | 50.0         | cost of a failed run                                |
    | render_mode | None         | "rgb_array": ``render()`` plots the last run        |
    | max_cycle_time_increase | None | constraint: the cycle time may grow by this share |
    | shaper      | None         | input shaper on both axes (zv, mzv, zvd, ei, …):    |
    |             |              | its frequency and damping become actions 11-14      |

    ## Version History

    * v0: initial version; ``info["is_success"]``, metrics in µm and s with the unit in
      their names, and ``reward_threshold`` added without a change of the dynamics or the
      reward.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 1}

    def __init__(self, *, machine: str | MachineConfig = "tomsk_xy",
                 program: str | Sequence[str] = "compact", randomize: bool = False,
                 weights: Weights | dict[str, float] | None = None, penalty: float = 50.0,
                 render_mode: str | None = None,
                 max_cycle_time_increase: float | None = None, shaper: str | None = None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError("render_mode", f"must be None or one of "
                              f"{self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self._last: tuple[RunOutcome, float] | None = None
        self._base = machine if isinstance(machine, MachineConfig) else load_machine(machine)
        if shaper is not None:
            self._base = self._base.with_overrides(shaper_overrides(shaper, "shaper"))
        dim = DIM + (len(SHAPER_NAMES) if all(
            getattr(self._base.controller.shaper, a).type != "none" for a in ("x", "y"))
            else 0)
        self._programs = (program,) if isinstance(program, str) else tuple(program)
        for p in self._programs:
            if p not in PROGRAMS:
                raise ConfigError("program", f"unknown tuning program {p!r}; valid: "
                                  f"{', '.join(PROGRAMS)}")
        self._randomizer = MachineRandomizer(self._base) if randomize else None
        self._weights = weights if isinstance(weights, Weights) else \
            Weights.from_mapping(weights)
        self._penalty = float(penalty)
        self._cycle_limit = max_cycle_time_increase
        self.action_space = gym.spaces.Box(-1.0, 1.0, (dim,), dtype=np.float32)
        n = len(METRICS)
        self.observation_space = gym.spaces.Box(-_ABS_CLIP, _ABS_CLIP, (3 * n + dim,),
                                                dtype=np.float32)
        self.tuning: Tuning | None = None
        self._best = np.zeros(n)
        self._best_cost = math.inf

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = options or {}
        cfg = options.get("machine")
        if cfg is None:
            cfg = self._randomizer.sample(self.np_random) if self._randomizer else self._base
        elif not isinstance(cfg, MachineConfig):
            cfg = load_machine(cfg)
        program = options.get("program") or self._programs[
            int(self.np_random.integers(len(self._programs)))]
        reuse = self.tuning is not None and self.tuning.cfg is cfg \
            and self.tuning.program == program
        if not reuse:   # a run is deterministic: the same machine keeps its baseline
            self.tuning = Tuning(cfg, program, weights=self._weights, penalty=self._penalty,
                                 max_cycle_time_increase=self._cycle_limit)
        base = self.tuning.baseline
        self._best = self.tuning.relative(base)
        self._best_cost = self.tuning.baseline_cost
        obs = self._observation(self.tuning, base, np.zeros(self.action_space.shape[0]))
        self._last = (base, self._best_cost)
        return obs, {"machine": cfg.name, "program": program,
                     "baseline_cost": self._best_cost,
                     "baseline_metrics": reported(base.metrics)}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self.tuning is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = check_action(action, self.action_space.shape[0])
        settings, outcome, terms = self.tuning.evaluate(a)
        cost = math.fsum(terms.values())
        if not outcome.failed and cost < self._best_cost:
            self._best_cost = cost
            self._best = self.tuning.relative(outcome)
        obs = self._observation(self.tuning, outcome, a)
        self._last = (outcome, cost)
        info = {"terms": terms, "cost": cost, "metrics": reported(outcome.metrics),
                "is_success": bool(not outcome.failed
                                   and cost < self.tuning.baseline_cost * (1 - 1e-12)),
                "diverged": outcome.diverged, "tripped": outcome.tripped,
                "status": outcome.status, "settings": settings.to_dict(),
                "sim_time": outcome.sim_time}
        return obs, -cost, outcome.failed, False, info

    @property
    def last_outcome(self) -> RunOutcome | None:
        """The last run's outcome (``metrics`` in SI), or None before ``reset``."""
        return None if self._last is None else self._last[0]

    def render(self) -> np.ndarray | None:
        """``render_mode="rgb_array"``: a plot of the last run, (H, W, 3) uint8. Each metric
        of the last run (and of the best so far) as a ratio to the analytic baseline, on a
        log scale, with the run's cost in the title; None without a render mode."""
        if self.render_mode is None or self.tuning is None or self._last is None:
            return None
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        outcome, cost = self._last
        last = np.exp(self.tuning.relative(outcome))
        best = np.exp(self._best)
        base = self.tuning.baseline.metrics
        zero = np.array([base[m] == 0.0 for m in METRICS])   # no ratio to a zero design
        fig = Figure(figsize=(6.4, 3.6), dpi=100)
        canvas = FigureCanvasAgg(fig)
        ax = fig.subplots()
        x = np.arange(len(METRICS))
        ax.bar(x[~zero] - 0.2, last[~zero], 0.4, label="last run")
        ax.bar(x[~zero] + 0.2, best[~zero], 0.4, label="best so far")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_yscale("log")
        for k in np.flatnonzero(zero):
            m = METRICS[k]
            unit, scale = ("s", 1.0) if "time" in m else ("µm", 1e6)
            value = outcome.metrics[m] * scale if not outcome.failed else math.nan
            ax.text(k, 1.0, f"analytic 0\nlast {value:.3g} {unit}", ha="center",
                    va="bottom", fontsize=6, color="0.3")
        ax.set_xticks(x, [m.replace("_", " ") for m in METRICS], rotation=30, ha="right",
                      fontsize=7)
        ax.set_ylabel("÷ analytic design")
        ax.set_title(f"{self.tuning.cfg.name}, {self.tuning.program}: cost {cost:.3f} "
                     f"({outcome.status})", fontsize=9)
        ax.legend(fontsize=7)
        fig.tight_layout()
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()

    def _observation(self, t: Tuning, outcome: RunOutcome, action: np.ndarray
                     ) -> np.ndarray:
        obs = np.concatenate([t.relative(outcome), t.descriptor(), action, self._best])
        return np.clip(obs, -_ABS_CLIP, _ABS_CLIP).astype(np.float32)
