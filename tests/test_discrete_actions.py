"""Discrete actions as Gymnasium means them: integers in range only, in the env and the vector env."""

from __future__ import annotations

import numpy as np
import pytest

from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.envs.vector import SolarChainVectorEnv

ACCEPTED = [7, np.int64(7), np.int32(7), np.uint8(7), np.array(7), np.array(7, dtype=np.int16)]
REFUSED = [
    3.7,
    -0.5,
    7.0,
    np.float64(7.0),
    [3, 100],
    [7],
    np.array([7]),
    "5",
    True,
    np.True_,
    np.array(True),
    np.zeros(3, dtype=np.float32),
    None,
]


@pytest.fixture(scope="module")
def env(tiny_dataset):
    return SolarChainEnv(tiny_dataset, action_mode="discrete")


@pytest.mark.parametrize("action", ACCEPTED, ids=repr)
def test_integer_actions_are_accepted(env, action):
    assert env.action_space.contains(action)
    env.reset(seed=0)
    _, _, _, _, info = env.step(action)
    expected = env.codec.discrete_table(env.config.discrete_levels)[7]
    assert (info["reward_ratio"], info["liquidity_ratio"], info["burn_rate"]) == expected


@pytest.mark.parametrize("action", REFUSED, ids=repr)
def test_non_integer_actions_are_refused(env, action):
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"a discrete action must be an integer in 0\.\.124"):
        env.step(action)


@pytest.mark.parametrize("action", [-1, 125, np.int64(-1), np.array(125)], ids=repr)
def test_out_of_range_actions_are_refused(env, action):
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"discrete action -?\d+ is outside 0\.\.124"):
        env.step(action)


def test_vector_env_takes_an_integer_array_of_one_action_per_sub_env(tiny_dataset):
    envs = SolarChainVectorEnv(3, tiny_dataset, action_mode="discrete")
    envs.reset(seed=1)
    _, _, _, _, info = envs.step(np.array([0, 7, 124]))
    table = envs.codec.discrete_table(envs.config.discrete_levels)
    assert info["reward_ratio"].tolist() == pytest.approx([table[i][0] for i in (0, 7, 124)], abs=0)
    envs.step([1, 2, 3])  # a list of ints is an integer array too
    for bad in (
        np.array([0.0, 7.0, 1.0]),
        np.array([[0], [7], [1]]),
        np.array([True, False, True]),
        [0, 7],
        ["1", "2", "3"],
        5,
    ):
        with pytest.raises(ValueError, match=r"expected 3 discrete actions as an integer array of shape \(3,\)"):
            envs.step(bad)
    with pytest.raises(ValueError, match=r"discrete actions must lie in 0\.\.124"):
        envs.step(np.array([0, 125, 1]))
