"""XYTable-GainTuning-v0: the checkers, reward = -Σ terms, determinism, failures, vector envs."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import envs
from envs.evaluation import METRICS, Weights
from envs.gain_tuning import GainTuningEnv
from twin.config import load_machine
from twin.errors import SimulationError
from twin.plant import Plant

KW = {"program": "tiny"}


def test_registered_ids():
    env = gym.make(envs.GAIN_TUNING_ID, **KW)
    assert env.spec.max_episode_steps == envs.GAIN_TUNING_RUNS
    assert isinstance(env.unwrapped, GainTuningEnv)
    # the threshold is the analytic design's reward when it never saturates (default weights)
    w = Weights()
    assert env.spec.reward_threshold == -(sum(getattr(w, m) for m in METRICS)
                                          - w.saturation_time)
    env.close()


def test_gymnasium_and_sb3_checkers_pass_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(envs.GAIN_TUNING_ID, **KW).unwrapped)
        sb3_check_env(GainTuningEnv(**KW))


def test_reward_is_minus_the_sum_of_the_terms():
    env = GainTuningEnv(**KW, weights={"overshoot": 2.0})
    _, info0 = env.reset(seed=0)
    for action in (np.zeros(11), np.full(11, 0.3), np.linspace(-1, 1, 11)):
        _, reward, _terminated, truncated, info = env.step(action.astype(np.float32))
        assert set(info["terms"]) == {*METRICS, "failure"}
        assert reward == pytest.approx(-sum(info["terms"].values()), rel=1e-12)
        assert not truncated
    # the zero action reproduces the baseline: every term equals its weight (or 0)
    _, reward, _, _, info = env.step(np.zeros(11, dtype=np.float32))
    assert reward == pytest.approx(-info0["baseline_cost"], rel=1e-12)
    assert info["terms"]["overshoot"] == pytest.approx(2.0)
    assert info["metrics"] == info0["baseline_metrics"]
    assert info["is_success"] is False                 # the analytic design beats nothing


def test_info_reports_metrics_in_micrometres_and_seconds_and_success():
    env = GainTuningEnv(**KW)
    _, info0 = env.reset(seed=0)
    rng = np.random.default_rng(3)
    for action in rng.uniform(-1, 1, (3, 11)).astype(np.float32):
        _, _, _, _, info = env.step(action)
        si = env.last_outcome.metrics
        for m in METRICS:
            unit = "s" if "time" in m else "um"
            factor = 1.0 if unit == "s" else 1e6
            got = info["metrics"][f"{m}_{unit}"]
            assert got == pytest.approx(si[m] * factor, rel=1e-12, nan_ok=True), m
        assert info["is_success"] == (not env.last_outcome.failed
                                      and info["cost"] < info0["baseline_cost"])


def test_observation_describes_the_last_run():
    env = GainTuningEnv(**KW)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    np.testing.assert_array_equal(obs[:8][[0, 1, 2, 3, 6]], 0.0)   # ln(baseline/baseline)
    a = np.full(11, -0.4, dtype=np.float32)
    obs, _, _, _, _ = env.step(a)
    np.testing.assert_allclose(obs[16:27], a, atol=1e-7)
    scales = env.tuning.scales
    for k, m in enumerate(METRICS):
        si = env.last_outcome.metrics[m]
        expected = np.clip(np.log(max(si / scales[m], 1e-12)), -5, 5)
        assert obs[k] == pytest.approx(expected, abs=1e-5)


def test_deterministic_under_a_seed_with_randomised_machines():
    a, b = GainTuningEnv(**KW, randomize=True), GainTuningEnv(**KW, randomize=True)
    oa, ia = a.reset(seed=11)
    ob, ib = b.reset(seed=11)
    np.testing.assert_array_equal(oa, ob)
    assert ia["baseline_metrics"] == ib["baseline_metrics"]
    _oc, ic = a.reset(seed=12)
    assert ic["baseline_metrics"] != ia["baseline_metrics"]   # another machine
    act = np.full(11, 0.2, dtype=np.float32)
    b.reset(seed=12)
    np.testing.assert_array_equal(a.step(act)[0], b.step(act)[0])


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_action_raises(bad):
    env = GainTuningEnv(**KW)
    env.reset(seed=0)
    a = np.zeros(11, dtype=np.float32)
    a[3] = bad
    with pytest.raises(ValueError, match="finite"):
        env.step(a)


def test_divergence_ends_the_episode_with_a_penalty(monkeypatch):
    env = GainTuningEnv(**KW, penalty=40.0)
    env.reset(seed=0)

    def diverge(self, volts, duration):
        raise SimulationError("the plant state diverged (not finite)")

    monkeypatch.setattr(Plant, "step", diverge)
    obs, reward, terminated, truncated, info = env.step(np.zeros(11, dtype=np.float32))
    assert terminated and not truncated
    assert info["diverged"] and not info["tripped"]
    assert reward == -40.0 == -sum(info["terms"].values())
    assert env.observation_space.contains(obs)


def test_trip_ends_the_episode_with_a_penalty():
    # a 45 µm trip threshold: the baseline (40 µm) passes, the jerk limit × 4 does not
    machine = load_machine("tomsk_xy").with_overrides(
        {"controller.regulator.following_error_limit": 45e-6})
    env = GainTuningEnv(**KW, machine=machine)
    env.reset(seed=0)
    a = np.zeros(11, dtype=np.float32)
    a[-1] = 1.0
    _, reward, terminated, _, info = env.step(a)
    assert info["tripped"] and not info["diverged"]
    assert info["status"] == "FOLLOWING_ERROR"
    assert terminated and reward == -50.0


def test_episode_is_truncated_by_the_time_limit():
    env = gym.make(envs.GAIN_TUNING_ID, **KW, weights=Weights())
    env.reset(seed=0)
    flags = [env.step(np.zeros(11, dtype=np.float32))[3] for _ in range(envs.GAIN_TUNING_RUNS)]
    assert flags == [False] * (envs.GAIN_TUNING_RUNS - 1) + [True]


def test_async_vector_env():
    vec = gym.vector.AsyncVectorEnv(
        [lambda: gym.make(envs.GAIN_TUNING_ID, **KW)] * 2, context="spawn")
    try:
        obs, _ = vec.reset(seed=[0, 0])
        np.testing.assert_array_equal(obs[0], obs[1])
        actions = np.stack([np.zeros(11), np.full(11, 0.25)]).astype(np.float32)
        _, rewards, _, _, _ = vec.step(actions)
        single = GainTuningEnv(**KW)
        single.reset(seed=0)
        assert rewards[1] == pytest.approx(single.step(actions[1])[1], rel=1e-12)
    finally:
        vec.close()


def test_the_namespaced_id_makes_without_an_import_and_renders_the_last_run():
    """``gym.make("envs:xy_twin/GainTuning-v0", render_mode="rgb_array")`` in a fresh
    interpreter that never imported ``envs``; ``render`` plots the last run."""
    import subprocess
    import sys

    code = ("import gymnasium as gym, numpy as np\n"
            "env = gym.make('envs:xy_twin/GainTuning-v0', program='tiny', "
            "render_mode='rgb_array')\n"
            "env.reset(seed=0)\n"
            "first = env.render()\n"
            "env.step(np.full(11, 0.5, dtype=np.float32))\n"
            "second = env.render()\n"
            "print(first.shape, first.dtype, int((first != second).any()), env.spec.id)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["(360,", "640,", "3)", "uint8", "1",
                                   "xy_twin/GainTuning-v0"]


def test_the_checkers_pass_with_the_render_mode():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(envs.GAIN_TUNING_ID, render_mode="rgb_array", **KW).unwrapped)
    with pytest.raises(Exception, match="render_mode"):
        GainTuningEnv(render_mode="human", **KW)


def test_the_cycle_time_constraint_costs_more_than_the_analytic_design():
    """``max_cycle_time_increase=0``: a jerk limit of J0/4 lengthens the cycle, and that
    run costs more than the analytic design; within the limit the term is 0."""
    env = GainTuningEnv(**KW, max_cycle_time_increase=0.0)
    _, info0 = env.reset(seed=0)
    slow = np.zeros(11, dtype=np.float32)
    slow[-1] = -1.0
    _, reward, _, _, info = env.step(slow)
    base = info0["baseline_metrics"]["cycle_time_s"]
    grown = info["metrics"]["cycle_time_s"] / base - 1.0
    assert grown > 0.0
    weight = sum(getattr(Weights(), m) for m in METRICS)
    assert info["terms"]["cycle_time_limit"] == pytest.approx(weight * (1 + 100 * grown))
    assert -reward > info0["baseline_cost"] and not info["is_success"]
    assert reward == pytest.approx(-sum(info["terms"].values()), rel=1e-12)
    _, _, _, _, info = env.step(np.zeros(11, dtype=np.float32))
    assert info["terms"]["cycle_time_limit"] == 0.0
    with pytest.raises(Exception, match="max_cycle_time_increase"):
        GainTuningEnv(**KW, max_cycle_time_increase=-0.1).reset(seed=0)


def test_the_shapers_frequency_and_damping_are_actions():
    """``shaper="ei"``: four more actions, which set the EI shapers the run uses (the
    controller's own shaper design, read back from a run with those settings)."""
    from twin.config.shaper_settings import SHAPER_TYPES
    from twin.controller.controller import Controller
    from twin.errors import ConfigError

    env = gym.make(envs.GAIN_TUNING_ID, machine="laser_belt", program="tiny", shaper="ei")
    assert env.action_space.shape == (15,) and env.observation_space.shape == (39,)
    env.reset(seed=0)
    rng = np.random.default_rng(2)
    a = np.zeros(15)
    a[11:] = rng.uniform(-1, 1, 4)
    _, _, _, _, info = env.step(a)
    space = env.unwrapped.tuning.space
    expect = space.decode(a)
    assert info["settings"]["shaper_frequency"] == [f for f, _ in expect.shaper]
    cfg = load_machine("laser_belt").with_overrides({**expect.overrides(), **{
        f"controller.shaper.{ax}.type": "ei" for ax in ("x", "y")}})
    built = Controller.from_machine(cfg, None).shaper.shapers
    assert [(s.name, s.frequency, s.damping) for s in built] == [
        ("ei", f, z) for f, z in expect.shaper]
    with pytest.raises(ConfigError) as exc:
        GainTuningEnv(machine="laser_belt", shaper="foo")
    assert exc.value.field == "shaper" and "none" in SHAPER_TYPES
