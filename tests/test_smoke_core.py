"""Quick end-to-end checks of the core on the tiny dataset."""

import gymnasium as gym
import numpy as np

import solarchain_eval  # noqa: F401


def test_env_runs_an_episode_on_the_tiny_dataset(tiny_dataset):
    env = gym.make("SolarChainEval-v0", data_dir=str(tiny_dataset))
    obs, info = env.reset(seed=3)
    assert obs.shape == (12,) and obs.dtype == np.float32
    assert info["episode_start_hour"] in (0, 24, 48, 72)
    total, steps = 0.0, 0
    truncated = False
    while not truncated:
        obs, reward, terminated, truncated, info = env.step(np.array([0.5, 0.5, 0.5], dtype=np.float32))
        assert not terminated
        total += reward
        steps += 1
    assert steps == 24
    assert np.isfinite(total)
    assert set(info["city_rewards"]) == {"Kunming", "Wuhan", "Xian"}
