"""Learned tuning: PPO or SAC (stable-baselines3) on ``xy_twin/GainTuning-v0``.

``train`` learns a tuning policy on randomised machines (``envs.randomize``) with
vectorised environments (``SubprocVecEnv`` for more than one) and saves checkpoints every
``checkpoint_steps``; asked to (``resume=True``, ``twin tune --resume``) it continues from the
newest checkpoint it wrote, so an interrupted training run goes on where it stopped.
``apply_policy`` runs a trained policy on a machine for a few tuning runs and keeps the best.

Security: a stable-baselines3 ``.zip`` (and a SAC replay buffer ``.pkl``) holds pickled
Python objects, and loading one runs code from it. This module loads exactly the file the
user names (``--policy FILE``, documented as trusted) and, only with ``resume``, the
checkpoints it wrote itself: every file it saves goes into a SHA-256 manifest
(``MANIFEST``) in the checkpoint folder, and a checkpoint is loaded only if its file and
its replay buffer hash to what the manifest holds. A file dropped into the folder, or
changed since, is refused; nothing is ever loaded because it was found by searching. (The
manifest guards against files planted or replaced in the folder, not against someone who
can also rewrite the manifest: keep the folder as private as the code.)
"""

from __future__ import annotations

import functools
import hashlib
import json
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
from twin.system.jsonio import load_json, write_json_atomic

__all__ = ["ALGORITHMS", "MANIFEST", "apply_policy", "latest_checkpoint", "train"]

ALGORITHMS = ("ppo", "sac")
MANIFEST = "checkpoints.sha256.json"
"""The checkpoint folder's manifest: ``{file name: SHA-256 hex}`` of every file ``train``
saved there."""
_PREFIX = "policy"
_STEPS = re.compile(rf"{_PREFIX}_(\d+)_steps\.zip$")


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _manifest(directory: Path) -> dict[str, str]:
    """The folder's manifest ({} if none, or if it is not one: then nothing is trusted)."""
    path = Path(directory) / MANIFEST
    try:
        doc = load_json(path.read_text(encoding="utf-8"), str(path))   # nesting bounded
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, ConfigError):
        return {}
    if not isinstance(doc, dict):
        return {}
    return {str(k): str(v) for k, v in doc.items() if isinstance(v, str)}


def _record(directory: Path, *files: Path) -> None:
    """Add (or update) ``files`` in the folder's manifest, atomically."""
    entries = _manifest(directory)
    for f in files:
        entries[f.name] = _sha256(f)
    write_json_atomic(Path(directory) / MANIFEST, entries, indent=1)


def _buffer_of(checkpoint: Path) -> Path:
    return checkpoint.with_name(checkpoint.name.replace("_steps.zip", "_steps.pkl").replace(
        _PREFIX, f"{_PREFIX}_replay_buffer"))


def _trusted(listed: dict[str, str], path: Path) -> bool:
    """``path`` is a file the manifest ``listed`` holds, unchanged since."""
    expected = listed.get(path.name)
    return expected is not None and path.is_file() and _sha256(path) == expected


def _algorithm(name: str) -> Any:
    from stable_baselines3 import PPO, SAC

    algos = {"ppo": PPO, "sac": SAC}
    if name not in algos:
        raise ConfigError("method", f"must be one of {', '.join(ALGORITHMS)}, got {name!r}")
    return algos[name]


def latest_checkpoint(directory: Path) -> Path | None:
    """The checkpoint with the most steps among those the manifest of ``directory`` lists,
    checked: None if there is none.

    Raises
    ------
    ConfigError
        (``resume``) The newest listed checkpoint, or its replay buffer, is missing or does
        not hash to the manifest's value (changed or replaced since it was written), or a
        newer checkpoint-like file lies in the folder that the manifest does not list: it
        is not loaded (loading it would run whatever it holds).
    """
    folder = Path(directory)
    listed = _manifest(folder)
    best: tuple[int, Path] | None = None
    stranger: tuple[int, Path] | None = None
    for p in folder.glob(f"{_PREFIX}_*_steps.zip"):
        m = _STEPS.search(p.name)
        if not m:
            continue
        steps = int(m.group(1))
        if p.name not in listed:
            stranger = max(stranger or (steps, p), (steps, p))
        elif best is None or steps > best[0]:
            best = (steps, p)
    if stranger is not None and (best is None or stranger[0] > best[0]):
        raise ConfigError("resume", f"{stranger[1]} is not in {folder / MANIFEST}: this job "
                          "did not write it; refusing to load it (a checkpoint is a pickle "
                          "and loading one runs its code)")
    if best is None:
        return None
    for f in (best[1], _buffer_of(best[1])):
        if (f.exists() or f.name in listed) and not _trusted(listed, f):
            raise ConfigError("resume", f"{f} does not match the SHA-256 in "
                              f"{folder / MANIFEST} (changed or replaced since this job "
                              "wrote it); refusing to load it")
    return best[1]


SAVE_S = 1.0
"""Seconds a training keeps at the end of its budget to save the policy and stop the
environments' processes."""


def _callbacks(directory: Path, every: int, n_envs: int, deadline: float,
               progress: Callable[[int], None] | None,
               on_cost: Callable[[float], None] | None = None) -> list[Any]:
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback

    class Budget(BaseCallback):
        """Stops training when the wall-time budget is spent (``deadline``, counted from
        the call's start: starting the environments is part of it); reports progress."""

        def _on_step(self) -> bool:
            if on_cost is not None:
                for info in self.locals.get("infos", ()):
                    if "cost" in info:
                        on_cost(float(info["cost"]))
            if progress is not None:
                progress(int(self.num_timesteps))
            return time.perf_counter() < deadline

    class Checkpoint(CheckpointCallback):
        """SB3's checkpoints, each file entered in the folder's manifest as it is saved."""

        def _on_step(self) -> bool:
            keep = super()._on_step()
            if self.n_calls % self.save_freq == 0:
                zip_path = Path(self._checkpoint_path(extension="zip"))
                buffer = Path(self._checkpoint_path("replay_buffer_", extension="pkl"))
                _record(directory, zip_path, *([buffer] if buffer.is_file() else []))
            return keep

    ckpt = Checkpoint(max(1, every // n_envs), str(directory), name_prefix=_PREFIX,
                      save_replay_buffer=True)
    return [ckpt, Budget()]


def train(method: str, *, machine: str | MachineConfig, program: str = "compact",
          out_dir: Path, total_steps: int, budget_s: float = math.inf, n_envs: int = 2,
          seed: int = 0, checkpoint_steps: int = 200, rollout: int = 64,
          weights: Weights | None = None, progress: Callable[[int], None] | None = None,
          resume: bool = False, on_cost: Callable[[float], None] | None = None,
          tensorboard: Path | None = None) -> Path:
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
        Wall-time budget of this call (s), from its start (the environments' start counts):
        training stops ``SAVE_S`` before it is spent, to save and close.
    n_envs : int
        Parallel environments (``SubprocVecEnv`` above 1).
    seed : int
    checkpoint_steps : int
        Checkpoint every this many tuning runs.
    rollout : int
        PPO: tuning runs per policy update (over all environments).
    resume : bool
        Continue from the newest checkpoint this job wrote in ``out_dir`` (checked against
        its manifest, ``latest_checkpoint``); without it training starts afresh whatever
        the folder holds.
    on_cost : callable(float), optional
        Called with the cost of every training run (the convergence plot's training panel).
    tensorboard : path, optional
        SB3's TensorBoard log folder (``tensorboard --logdir PATH``): losses, episode
        rewards, learning rate, one run per call (``<method>_<n>``).

    Raises
    ------
    ConfigError
        ``resume`` and a checkpoint that fails its check.
    """
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    deadline = time.perf_counter() + budget_s - SAVE_S
    algo = _algorithm(method)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tb = None if tensorboard is None else str(tensorboard)
    kwargs = {"machine": machine, "program": program, "randomize": True, "weights": weights}
    factories = [functools.partial(_make_env, kwargs, seed + i) for i in range(n_envs)]
    vec = SubprocVecEnv(factories, start_method="spawn") if n_envs > 1 \
        else DummyVecEnv(factories)
    try:
        start = latest_checkpoint(out) if resume else None
        if start is not None:   # our own checkpoint, as written: trusted
            model = algo.load(start, env=vec, tensorboard_log=tb)
            buffer = _buffer_of(start)
            if method == "sac" and buffer.is_file():
                model.load_replay_buffer(buffer)
        else:
            model = algo("MlpPolicy", vec, seed=seed, verbose=0, tensorboard_log=tb,
                         **_hyper(method, n_envs, rollout))
        if tb is None:   # SB3's own default logger makes an empty /tmp/SB3-<time> folder
            model.set_logger(Logger(folder=None, output_formats=[]))
        left = total_steps - int(model.num_timesteps)
        if left > 0:
            model.learn(left, callback=_callbacks(out, checkpoint_steps, n_envs, deadline,
                                                  progress, on_cost),
                        reset_num_timesteps=False, tb_log_name=method)
        path = out / "policy.zip"
        model.save(path)
        _record(out, path)
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
                      info["terms"], dict(env.last_outcome.metrics), info["status"],
                      info["settings"], 0.0, info["sim_time"])
        trials.append(trial)
        if on_trial is not None:
            on_trial(trial)
        if terminated:
            break
    return trials, baseline

