"""Gymnasium contracts of the single and vector environments."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import solarchain_eval  # noqa: F401  (registers the env)
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.envs.vector import SolarChainVectorEnv
from solarchain_eval.evaluation.rollout import STEP_FIELDS

F32 = np.float32


@pytest.mark.parametrize("mode", ["continuous", "discrete"])
def test_passes_gymnasium_env_checker(tiny_dataset, mode):
    env = gym.make("SolarChainEval-v0", data_dir=str(tiny_dataset), action_mode=mode)
    check_env(env.unwrapped, skip_render_check=True)
    assert isinstance(env.action_space, gym.spaces.Discrete if mode == "discrete" else gym.spaces.Box)
    if mode == "discrete":
        assert env.action_space.n == 125


def test_make_without_data_dir_uses_the_embedded_default_dataset(isolated_cache):
    env = gym.make("SolarChainEval-v0")
    obs, info = env.reset(seed=1)
    assert obs.shape == (12,)
    assert env.unwrapped.table.hours == 720
    assert str(isolated_cache) in env.unwrapped.table.source


def test_info_carries_every_record_field_and_cost(tiny_dataset):
    env = SolarChainEnv(tiny_dataset)
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step(np.array([0.3, 0.9, 0.1], F32))
    assert set(STEP_FIELDS) <= set(info)
    assert info["reward"] == reward and not terminated and not truncated
    assert info["cost"] == info["physics_violation_rate"] + info["unsafe_backed_MWh"]
    assert list(info["city_rewards"]) == ["Kunming", "Wuhan", "Xian"]


def test_episode_truncates_after_24_steps_and_refuses_further_steps(tiny_dataset):
    env = SolarChainEnv(tiny_dataset)
    env.reset(seed=0)
    flags = [env.step(np.full(3, 0.5, F32))[3] for _ in range(24)]
    assert flags == [False] * 23 + [True]
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(np.full(3, 0.5, F32))


def test_bad_actions_are_rejected_with_a_clear_message(tiny_dataset):
    env = SolarChainEnv(tiny_dataset)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="3 components"):
        env.step(np.zeros(4, F32))
    discrete = SolarChainEnv(tiny_dataset, action_mode="discrete")
    discrete.reset(seed=0)
    with pytest.raises(ValueError, match="outside 0..124"):
        discrete.step(125)


def test_start_hour_option_and_reset_seeding(tiny_dataset):
    env = SolarChainEnv(tiny_dataset)
    hours = env.table.hours
    assert hours == 96  # four days: starts 0, 24, 48, 72
    _, info = env.reset(options={"start_hour": 10_000})
    assert info["episode_start_hour"] == hours - 24
    a, _ = env.reset(seed=42)
    b, _ = env.reset(seed=42)
    assert np.array_equal(a, b)
    # Starts are midnights drawn as rng.choice of the admissible starts.
    starts = np.arange(0, hours - 24 + 1, 24)
    expected = np.random.default_rng(42).choice(starts)
    assert env.reset(seed=42)[1]["episode_start_hour"] == expected


def _sequential_reference(seed: int, steps_per_episode: list[int], hours: int) -> list[tuple[int, list[float]]]:
    """What drawing one shock per step (the original release) gives: (start, shocks) per episode."""
    rng = np.random.default_rng(seed)
    starts = np.arange(0, hours - 24 + 1, 24)
    episodes = []
    for steps in steps_per_episode:
        start = int(rng.choice(starts))
        episodes.append((start, [float(rng.normal(0.0, 0.004)) for _ in range(steps)]))
    return episodes


def test_cutting_episodes_short_keeps_the_random_stream_of_sequential_drawing(tiny_dataset):
    lengths = [24, 7, 0, 24, 13, 24] + [24] * 70 + [3, 24]  # crosses the 64-episode checkpoint
    env = SolarChainEnv(tiny_dataset)
    reference = _sequential_reference(5, lengths, env.table.hours)
    vec = SolarChainVectorEnv(2, tiny_dataset)
    vec.reset(seed=[5, 99])
    action = np.array([0.4, 0.6, 0.2], F32)
    for episode, steps in enumerate(lengths):
        _, info = env.reset(seed=5) if episode == 0 else env.reset()
        if episode:
            vec.reset(options={"reset_mask": np.array([True, False])})
        start, shocks = reference[episode]
        assert info["episode_start_hour"] == start == vec._start[0]
        assert env._noise[:steps] == pytest.approx(shocks, rel=0, abs=0)
        assert list(vec._noise[0, :steps]) == shocks
        for _ in range(steps):
            env.step(action)
            vec.step(np.stack([action, action]))


@pytest.mark.parametrize("autoreset", ["NextStep", "SameStep"])
@pytest.mark.parametrize("mode", ["continuous", "discrete"])
def test_vector_sub_envs_equal_single_envs(tiny_dataset, autoreset, mode):
    n, calls = 4, 60
    vec = gym.make_vec(
        "SolarChainEval-v0",
        num_envs=n,
        vectorization_mode="vector_entry_point",
        data_dir=str(tiny_dataset),
        action_mode=mode,
        autoreset_mode=autoreset,
    )
    rng = np.random.default_rng(11)
    if mode == "continuous":
        actions = rng.random((calls, n, 3), dtype=F32) * 1.4 - 0.2
        actions[3, 1] = np.nan
        actions[5, 2, 0], actions[6, 0, 1] = np.inf, -np.inf
        actions[7, :, 0] = 1.0  # α at the top of its range (the clip binds)
    else:
        actions = rng.integers(0, 125, size=(calls, n))
    obs, _ = vec.reset(seed=200)
    history = [vec.step(actions[t]) for t in range(calls)]
    for i in range(n):
        env = SolarChainEnv(tiny_dataset, action_mode=mode)
        single_obs, _ = env.reset(seed=200 + i)
        assert np.array_equal(single_obs, obs[i])
        for t, (v_obs, v_rew, _v_term, v_trunc, v_info) in enumerate(history):
            if not v_info:  # NEXT_STEP reset call
                single_obs, _ = env.reset()
                assert np.array_equal(single_obs, v_obs[i]) and v_rew[i] == 0.0
                continue
            single_obs, reward, _, truncated, info = env.step(actions[t, i])
            assert reward == v_rew[i] and truncated == v_trunc[i]
            for key in STEP_FIELDS:
                assert info[key] == v_info[key][i], (key, t)
            assert list(info["city_rewards"].values()) == list(v_info["city_rewards"][i])
            if truncated and autoreset == "SameStep":
                assert np.array_equal(single_obs, v_info["final_obs"][i])
                single_obs, _ = env.reset()
            assert np.array_equal(single_obs, v_obs[i])
