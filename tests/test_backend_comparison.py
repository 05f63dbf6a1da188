"""The backend comparison: per policy × setting differences with start-day bootstrap intervals."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from solarchain_eval.report.compare import compare_runs


def _metrics(reward: np.ndarray, policy: str = "ppo") -> pd.DataFrame:
    n = reward.size
    return pd.DataFrame(
        {
            "policy": policy,
            "setting": "main",
            "run_seed": 1,
            "episode": np.arange(n),
            "episode_seed": 1 + np.arange(n),
            "start_hour": 24 * (np.arange(n) % 5),
            "cumulative_reward": reward,
        }
    )


def test_a_constant_shift_is_recovered_exactly_and_noise_gets_an_interval():
    rng = np.random.default_rng(3)
    base = _metrics(rng.normal(size=40))
    shifted = base.assign(cumulative_reward=base["cumulative_reward"] + 1.5)
    row = compare_runs(base, shifted, ["cumulative_reward"]).iloc[0]
    assert row["difference"] == pytest.approx(1.5) and row["low"] == pytest.approx(1.5)
    assert row["high"] == pytest.approx(1.5)
    noisy = base.assign(cumulative_reward=base["cumulative_reward"] + rng.normal(0.5, 1.0, 40))
    row = compare_runs(base, noisy, ["cumulative_reward"]).iloc[0]
    expected = noisy["cumulative_reward"].mean() - base["cumulative_reward"].mean()
    assert row["difference"] == pytest.approx(expected) and row["low"] < expected < row["high"]
    assert row["base"] == pytest.approx(base["cumulative_reward"].mean())


def test_different_episodes_are_refused_and_unshared_policies_skipped():
    base = _metrics(np.zeros(10))
    other = base.assign(episode_seed=base["episode_seed"] + 1)
    with pytest.raises(ValueError, match="different episodes"):
        compare_runs(base, other, ["cumulative_reward"])
    only_base = pd.concat([base, _metrics(np.zeros(10), "dqn")])
    assert list(compare_runs(only_base, base, ["cumulative_reward"])["policy"]) == ["ppo"]
