"""XYTable-Servo-v0: the checkers, the zero action is the plain controller, rewards, errors."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv

import envs
from envs.programs import tuning_program
from envs.servo import ServoEnv
from twin.config import load_machine
from twin.controller.controller import Controller
from twin.errors import ConfigError, SimulationError
from twin.hardware.sim import SimDriver
from twin.plant import Plant
from twin.session.run import axis_models


def _episode(env, action_fn, seed=0):
    obs, _ = env.reset(seed=seed)
    rows, done = [], False
    while not done:
        obs, reward, terminated, truncated, info = env.step(action_fn(obs))
        rows.append((reward, info))
        done = terminated or truncated
    return rows


def test_checkers_pass_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(envs.SERVO_ID).unwrapped)
        sb3_check_env(ServoEnv())


def test_zero_action_reproduces_the_plain_controller():
    """Reference: the same program on the same machine without the env."""
    cfg = load_machine("tomsk_xy")
    plant = Plant.from_machine(cfg)
    plant.reset()
    start = plant.truth().table_position
    ctrl = Controller.from_machine(cfg, tuning_program("tiny", cfg, start),
                                   axis_models=axis_models(cfg), start=start)
    drv = SimDriver(plant, cfg.controller.period)
    errors = []
    while not ctrl.done:
        drv.write(ctrl.tick(drv.read()))
        errors.append(ctrl.regulator.error.copy())
    rows = _episode(ServoEnv(), lambda obs: np.zeros(2, dtype=np.float32))
    env_errors = [info["following_error"] for _, info in rows]
    # the env ticks once in reset: its step k sees the plain loop's tick k + 1
    np.testing.assert_array_equal(np.array(env_errors), np.array(errors[1:]))
    assert rows[-1][1]["status"] == "FINISHED"


def test_reward_is_minus_the_sum_of_the_terms():
    env = ServoEnv(error_scale=20e-6, w_effort=0.5)
    rng = np.random.default_rng(0)
    rows = _episode(env, lambda obs: rng.uniform(-1, 1, 2).astype(np.float32))
    for reward, info in rows[:50]:
        assert reward == pytest.approx(-sum(info["terms"].values()), rel=1e-12)
        e = info["following_error"] / 20e-6
        assert info["terms"]["tracking"] == pytest.approx(np.mean(e * e), rel=1e-12)


def test_a_correction_changes_the_error():
    push = _episode(ServoEnv(), lambda obs: np.array([1.0, 0.0], dtype=np.float32))
    rest = _episode(ServoEnv(), lambda obs: np.zeros(2, dtype=np.float32))
    assert push[20][1]["following_error"][0] != rest[20][1]["following_error"][0]
    assert push[20][1]["following_error"][1] == rest[20][1]["following_error"][1]


@pytest.mark.parametrize("bad", [[np.nan, 0.0], [0.0, np.inf]])
def test_non_finite_action_raises(bad):
    env = ServoEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array(bad, dtype=np.float32))


def test_divergence_ends_the_episode(monkeypatch):
    env = ServoEnv(penalty=9.0)
    env.reset(seed=0)

    def diverge(self, volts, duration):
        raise SimulationError("diverged")

    monkeypatch.setattr(Plant, "step", diverge)
    _, reward, terminated, _, info = env.step(np.zeros(2, dtype=np.float32))
    assert terminated and info["diverged"] and reward == pytest.approx(-9.0)


def test_bad_arguments():
    with pytest.raises(ConfigError, match="max_correction"):
        ServoEnv(max_correction=0.0)
    with pytest.raises(ConfigError, match="program"):
        ServoEnv(program="nope")


def test_subproc_vec_env():
    vec = make_vec_env(f"envs:{envs.SERVO_ID}", n_envs=2, seed=0, vec_env_cls=SubprocVecEnv,
                       vec_env_kwargs={"start_method": "spawn"})
    try:
        obs = vec.reset()
        assert obs.shape == (2, 10)
        obs, rewards, dones, _infos = vec.step(np.zeros((2, 2), dtype=np.float32))
        assert rewards[0] == pytest.approx(rewards[1]) and not dones.any()
    finally:
        vec.close()


def test_render_plots_the_episode_and_the_checker_passes_with_it():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make("xy_twin/Servo-v0", render_mode="rgb_array").unwrapped)
    env = gym.make("xy_twin/Servo-v0", render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    for _ in range(100):
        env.step(np.zeros(2, dtype=np.float32))
    later = env.render()
    assert first.shape == later.shape == (360, 640, 3) and later.dtype == np.uint8
    assert (first != later).any()
    env.close()
