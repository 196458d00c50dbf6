"""Learned tuning: PPO or SAC (stable-baselines3) on ``XYTable-GainTuning-v0``.

``train`` learns a tuning policy on randomised machines (``envs.randomize``) with
vectorised environments (``SubprocVecEnv`` for more than one), saves checkpoints every
``checkpoint_steps`` and resumes from the newest checkpoint in its directory, so an
interrupted training run continues where it stopped. ``apply_policy`` runs a trained policy
on a machine for a few tuning runs and keeps the best.

Security: a stable-baselines3 ``.zip`` holds pickled Python objects, and loading one runs
code from it. Load only policies you trained yourself or got from a trusted source; this
module loads exactly the file the user names (``--policy FILE``) and the checkpoints it
wrote itself, never anything found by searching.
"""

from __future__ import annotations

import functools
import math
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from envs import GAIN_TUNING_RUNS
from envs.evaluation import Weights
from envs.gain_tuning import GainTuningEnv
from tuning.evaluator import Trial, baseline_trial
from twin.config import MachineConfig
from twin.errors import ConfigError

__all__ = ["ALGORITHMS", "apply_policy", "latest_checkpoint", "train"]

ALGORITHMS = ("ppo", "sac")
_PREFIX = "policy"
_STEPS = re.compile(rf"{_PREFIX}_(\d+)_steps\.zip$")


def _algorithm(name: str) -> Any:
    from stable_baselines3 import PPO, SAC

    algos = {"ppo": PPO, "sac": SAC}
    if name not in algos:
        raise ConfigError("method", f"must be one of {', '.join(ALGORITHMS)}, got {name!r}")
    return algos[name]


def latest_checkpoint(directory: Path) -> Path | None:
    """The checkpoint with the most steps in ``directory`` (written by ``train``), if any."""
    best: tuple[int, Path] | None = None
    for p in Path(directory).glob(f"{_PREFIX}_*_steps.zip"):
        m = _STEPS.search(p.name)
        if m and (best is None or int(m.group(1)) > best[0]):
            best = (int(m.group(1)), p)
    return None if best is None else best[1]


def _callbacks(directory: Path, every: int, n_envs: int, budget_s: float,
               progress: Callable[[int], None] | None) -> list[Any]:
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback

    class Budget(BaseCallback):
        """Stops training when the wall-time budget is spent; reports progress."""

        def _on_training_start(self) -> None:
            self.start = time.perf_counter()

        def _on_step(self) -> bool:
            if progress is not None:
                progress(int(self.num_timesteps))
            return time.perf_counter() - self.start < budget_s

    ckpt = CheckpointCallback(max(1, every // n_envs), str(directory), name_prefix=_PREFIX,
                              save_replay_buffer=True)
    return [ckpt, Budget()]


def train(method: str, *, machine: str | MachineConfig, program: str = "compact",
          out_dir: Path, total_steps: int, budget_s: float = math.inf, n_envs: int = 2,
          seed: int = 0, checkpoint_steps: int = 200, rollout: int = 64,
          weights: Weights | None = None, progress: Callable[[int], None] | None = None
          ) -> Path:
    """Train (or resume training) a tuning policy; returns the saved ``policy.zip``.

    Parameters
    ----------
    method : {"ppo", "sac"}
    machine : str or MachineConfig
        The nominal machine; every episode draws a random variant of it.
    program : str
        Tuning program of the episodes.
    out_dir : path
        Checkpoints (``policy_<steps>_steps.zip``) and the final ``policy.zip``.
    total_steps : int
        Tuning runs to train for, counting those of a resumed run.
    budget_s : float
        Wall-time budget of this call (s): training stops (and saves) when it is spent.
    n_envs : int
        Parallel environments (``SubprocVecEnv`` above 1).
    seed : int
    checkpoint_steps : int
        Checkpoint every this many tuning runs.
    rollout : int
        PPO: tuning runs per policy update (over all environments).
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    algo = _algorithm(method)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kwargs = {"machine": machine, "program": program, "randomize": True, "weights": weights}
    factories = [functools.partial(_make_env, kwargs, seed + i) for i in range(n_envs)]
    vec = SubprocVecEnv(factories, start_method="spawn") if n_envs > 1 \
        else DummyVecEnv(factories)
    try:
        resume = latest_checkpoint(out)
        if resume is not None:   # our own checkpoint: trusted
            model = algo.load(resume, env=vec)
            buffer = resume.with_name(resume.name.replace(
                "_steps.zip", "_steps.pkl").replace(_PREFIX, f"{_PREFIX}_replay_buffer"))
            if method == "sac" and buffer.is_file():
                model.load_replay_buffer(buffer)
        else:
            model = algo("MlpPolicy", vec, seed=seed, verbose=0,
                         **_hyper(method, n_envs, rollout))
        left = total_steps - int(model.num_timesteps)
        if left > 0:
            model.learn(left, callback=_callbacks(out, checkpoint_steps, n_envs, budget_s,
                                                  progress),
                        reset_num_timesteps=False)
        path = out / "policy.zip"
        model.save(path)
    finally:
        vec.close()
    return path


def _make_env(kwargs: dict[str, Any], seed: int) -> gym.Env:
    """A monitored, time-limited gain-tuning env seeded with ``seed`` (picklable factory
    for ``SubprocVecEnv``)."""
    from stable_baselines3.common.monitor import Monitor

    env = Monitor(gym.wrappers.TimeLimit(GainTuningEnv(**kwargs),
                                         max_episode_steps=GAIN_TUNING_RUNS))
    env.reset(seed=seed)
    return env


def _hyper(method: str, n_envs: int, rollout: int) -> dict[str, Any]:
    """Small-sample settings: every step is a whole simulated program run."""
    if method == "ppo":
        n_steps = max(2, rollout // n_envs)
        return {"n_steps": n_steps, "batch_size": max(2, n_steps * n_envs // 2),
                "n_epochs": 10,
                "learning_rate": 1e-3, "gamma": 0.9, "gae_lambda": 0.9, "ent_coef": 0.0,
                "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -1.0}}
    return {"learning_starts": min(64, rollout), "batch_size": 64, "buffer_size": 100_000,
            "learning_rate": 1e-3, "gamma": 0.9, "train_freq": 1,
            "policy_kwargs": {"net_arch": [64, 64]}}


def apply_policy(policy: Path, machine: str | MachineConfig, *, program: str = "compact",
                 runs: int = 5, weights: Weights | None = None,
                 on_trial: Callable[[Trial], None] | None = None
                 ) -> tuple[list[Trial], Trial]:
    """Tune ``machine`` with a trained policy in ``runs`` tuning runs.

    ``policy`` must be a file the user named and trusts (see the module docstring). The
    policy acts deterministically from the analytic baseline's observation.

    Returns
    -------
    trials : list of Trial
        The runs, in order.
    baseline : Trial
        The analytic design's run.
    """
    from stable_baselines3.common.base_class import BaseAlgorithm

    path = Path(policy)
    if not path.is_file():
        raise ConfigError("policy", f"no such file: {policy}")
    model: BaseAlgorithm | None = None
    for name in ALGORITHMS:
        try:
            model = _algorithm(name).load(path, device="cpu")
            break
        except (ValueError, KeyError, TypeError, AttributeError):
            continue
    if model is None:
        raise ConfigError("policy", f"{policy} is not a PPO or SAC policy")
    env = GainTuningEnv(machine=machine, program=program, weights=weights)
    obs, _ = env.reset(seed=0)
    if env.tuning is None:
        raise gym.error.ResetNeeded("the env did not set up its tuning")
    baseline = baseline_trial(env.tuning)
    trials: list[Trial] = []
    for _ in range(runs):
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, _, info = env.step(action)
        trial = Trial(tuple(float(v) for v in np.clip(action, -1, 1)), -float(reward),
                      info["terms"], info["metrics"], info["status"], info["settings"],
                      0.0, info["sim_time"])
        trials.append(trial)
        if on_trial is not None:
            on_trial(trial)
        if terminated:
            break
    return trials, baseline

