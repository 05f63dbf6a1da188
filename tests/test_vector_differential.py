"""Differential test: every sub-env of the vector env is a single env, bit for bit.

Random programs of steps and masked resets drive a :class:`SolarChainVectorEnv` and, beside
it, one :class:`SolarChainEnv` per sub-env. Subsets of sub-envs reset at random steps (with
and without new seeds or fixed start hours), so episodes end at different calls and the
partial-reset and partial-commit paths run; both autoreset modes, both action modes, random
and non-finite actions, episodes shorter and longer than the table. Every observation,
reward, flag and ``info`` entry of every sub-env must equal the single env's.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.data.table import load_table
from solarchain_eval.envs import rng_stream as episodes
from solarchain_eval.envs import vector
from solarchain_eval.envs.env import STEP_INFO_KEYS, SolarChainEnv
from solarchain_eval.envs.vector import SolarChainVectorEnv

F32 = np.float32
# The tiny dataset has 96 hours: 96-step episodes have a single start (hour 0) and use every hour;
# longer episodes are refused when the env is built (docs/input_validation.md).
EPISODE_STEPS = (1, 2, 3, 5, 24, 95, 96)
actions_f32 = st.floats(-0.5, 1.5, width=32) | st.floats(width=32, allow_nan=True, allow_infinity=True)


@st.composite
def programs(draw: st.DrawFn) -> tuple:
    n = draw(st.integers(1, 4))
    mode = draw(st.sampled_from(["continuous", "discrete"]))
    autoreset = draw(st.sampled_from(["NextStep", "SameStep"]))
    episode_steps = draw(st.sampled_from(EPISODE_STEPS))
    seed = draw(st.integers(0, 2**31))
    # 17:00 to 19:00: short episodes see the price rise, then fall after sunset.
    first_hour = draw(st.integers(17, 19) | st.integers(0, 23))
    ops: list[tuple] = []
    for _ in range(draw(st.integers(1, 60))):
        if draw(st.integers(0, 3)) == 0:
            mask = draw(st.lists(st.booleans(), min_size=n, max_size=n))
            seeds = draw(st.none() | st.lists(st.none() | st.integers(0, 2**31), min_size=n, max_size=n))
            start_hour = draw(st.none() | st.integers(-5, 120))
            ops.append(("reset", mask, seeds, start_hour))
        elif mode == "continuous":
            ops.append(("step", draw(arrays(F32, (n, 3), elements=actions_f32))))
        else:
            ops.append(("step", draw(arrays(np.int64, (n,), elements=st.integers(0, 124)))))
    return n, mode, autoreset, episode_steps, first_hour, seed, ops


def same(a: object, b: object) -> bool:
    """Bit-for-bit equality (NaN equals NaN, -0.0 differs from 0.0)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "f" or b.dtype.kind == "f":
        a, b = a.astype(np.float64), b.astype(np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.fixture(scope="module")
def tiny_tables(tiny_dataset):
    """The tiny dataset's table with its hours rolled to begin at each hour of the day.

    Episodes start at the table's midnights, and the price falls through every night hour:
    a stale peak price only shows where an episode's price rises and then falls, so the
    programs draw which hour of the day episodes begin at.
    """
    table = load_table(tiny_dataset)
    arrays = [field.name for field in dataclasses.fields(table) if isinstance(getattr(table, field.name), np.ndarray)]
    return [
        dataclasses.replace(
            table,
            fingerprint=f"{table.fingerprint}-from-{hour}h",
            **{name: np.roll(getattr(table, name), -hour, axis=0) for name in arrays},
        )
        for hour in range(24)
    ]


@pytest.fixture
def frequent_checkpoints(monkeypatch):
    # Generator snapshots every 3 episodes, so the programs cross many of them.
    monkeypatch.setattr(episodes, "CHECKPOINT_EVERY", 3)
    monkeypatch.setattr(vector, "CHECKPOINT_EVERY", 3)


@given(program=programs())
@settings(
    max_examples=200, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
def test_every_sub_env_equals_a_single_env_bit_for_bit(tiny_tables, frequent_checkpoints, program):
    n, mode, autoreset, episode_steps, first_hour, seed, ops = program
    tiny_table = tiny_tables[first_hour]
    cfg = BenchmarkConfig().with_updates(episode_steps=episode_steps, action_mode=mode)
    vec = SolarChainVectorEnv(n, config=cfg, table=tiny_table, autoreset_mode=autoreset)
    singles = [SolarChainEnv(config=cfg, table=tiny_table) for _ in range(n)]
    obs, info = vec.reset(seed=seed)
    expected_obs = []
    for i, env in enumerate(singles):
        single_obs, single_info = env.reset(seed=seed + i)
        assert single_info["episode_start_hour"] == info["episode_start_hour"][i]
        expected_obs.append(single_obs)
    awaiting_reset = [False] * n  # NEXT_STEP: the next step call resets this sub-env
    for call, op in enumerate(ops):
        if op[0] == "reset":
            _, mask, seeds, start_hour = op
            options = {"reset_mask": np.array(mask)} | ({} if start_hour is None else {"start_hour": start_hour})
            obs, info = vec.reset(seed=seeds, options=options)
            assert list(info["_episode_start_hour"]) == mask
            for i in np.flatnonzero(mask):
                single_seed = None if seeds is None else seeds[i]
                expected_obs[i], single_info = singles[i].reset(
                    seed=single_seed, options=None if start_hour is None else {"start_hour": start_hour}
                )
                assert single_info["episode_start_hour"] == info["episode_start_hour"][i], (call, i)
                awaiting_reset[i] = False
        else:
            actions = op[1]
            obs, reward, terminated, truncated, info = vec.step(actions)
            assert not terminated.any()
            for i, env in enumerate(singles):
                if awaiting_reset[i]:
                    expected_obs[i], _ = env.reset()
                    awaiting_reset[i] = False
                    assert reward[i] == 0.0 and not truncated[i], (call, i)
                    assert not info or not any(info["_" + key][i] for key in STEP_INFO_KEYS), (call, i)
                    continue
                single_obs, single_reward, _, single_truncated, single_info = env.step(actions[i])
                assert same(single_reward, reward[i]) and single_truncated == truncated[i], (call, i)
                for key in STEP_INFO_KEYS:
                    assert info["_" + key][i] and same(single_info[key], info[key][i]), (call, i, key)
                assert same(list(single_info["city_rewards"].values()), info["city_rewards"][i]), (call, i)
                if single_truncated and autoreset == "SameStep":
                    assert info["_final_obs"][i] and same(single_obs, info["final_obs"][i]), (call, i)
                    single_obs, _ = env.reset()
                elif single_truncated:
                    awaiting_reset[i] = True
                expected_obs[i] = single_obs
        for i in range(n):
            assert same(expected_obs[i], obs[i]), (call, i, "observation")
