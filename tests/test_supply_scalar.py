"""The single env's specialised scalar step equals the generic ``supply_step(SCALAR, ...)`` bit for bit,
and the single env's step equals one assembled from the generic pieces (NaN, infinities and -0.0 included)."""

from __future__ import annotations

import math
import struct
import sys

import numpy as np
import pytest

from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.supply import scalar
from solarchain_eval.supply.dynamics import SCALAR, SupplyParams, SupplyRewardWeights, supply_step
from solarchain_eval.supply.env import STEP_FIELDS, SupplyChainEnv
from solarchain_eval.supply.inputs import _INITIAL_PREV, decode_actions, jitter_of, step_record
from solarchain_eval.supply.scalar import ScalarSupplyStep
from supply_fixtures import supply_dir, supply_table  # noqa: F401

_ODD = (math.nan, math.inf, -math.inf, -0.0, 0.0, 1e-300)


def _bits(value):
    """A value with every float replaced by its IEEE bytes (-0.0 != 0.0), lists and dicts kept.

    Every NaN maps to one value: IEEE 754 leaves which operand's NaN (payload and sign) an addition of
    two NaNs returns unspecified, and a C compiler may commute the operands (CPython's float ``+`` and
    its builtin ``sum`` are compiled separately), so only NaN-ness is reproducible.
    """
    if isinstance(value, float):
        return b"nan" if math.isnan(value) else struct.pack("<d", value)
    if isinstance(value, (list, tuple)):
        return type(value)(_bits(v) for v in value)
    if isinstance(value, dict):
        return {k: _bits(v) for k, v in value.items()}
    return value


def _value(rng: np.random.Generator, low: float, high: float) -> float:
    """A uniform draw, or (one time in eight) a NaN, an infinity, a signed zero or a tiny value."""
    if rng.random() < 0.125:
        return _ODD[rng.integers(len(_ODD))]
    return float(rng.uniform(low, high))


@pytest.mark.parametrize("builtin_sum", [True, False])  # the builtin sum (CPython < 3.12) or the loops
@pytest.mark.parametrize("penalty", [True, False])
def test_the_scalar_step_equals_the_generic_one_bit_for_bit(supply_table, penalty, builtin_sum, monkeypatch):  # noqa: F811
    monkeypatch.setattr(scalar, "_SEQUENTIAL_SUM", builtin_sum and sys.version_info < (3, 12))
    params = SupplyParams.from_table(supply_table)
    weights = SupplyRewardWeights.from_config(BenchmarkConfig(no_physics_penalty=not penalty))
    rng = np.random.default_rng(11)
    regions, days = len(params.lead_time_days), 6
    orders = [[_value(rng, 0.0, 40.0) for _ in range(regions)] for _ in range(days)]
    spoofed = [[bool(rng.random() < 0.4) for _ in range(regions)] for _ in range(days)]
    levels = [[_value(rng, 0.0, 400.0) for _ in range(regions)] for _ in range(days)]
    fast = ScalarSupplyStep(params, weights, orders, spoofed, levels)
    odd = 0
    for _ in range(400):
        day = int(rng.integers(days))
        on_hand = [_value(rng, -5.0, 300.0) for _ in range(regions)]
        pipeline = [[_value(rng, 0.0, 40.0) for _ in range(lead)] for lead in params.lead_time_days]
        backlog = [_value(rng, 0.0, 50.0) for _ in range(regions)]
        price, peak = _value(rng, 0.0, 2.0), _value(rng, 0.5, 2.0)
        action = (_value(rng, 0.0, 1.0), _value(rng, 0.0, 1.0), _value(rng, 0.0, 1.0))
        jitter, noise = _value(rng, 0.0, 3.0), _value(rng, -0.02, 0.02)
        args = (on_hand, pipeline, backlog, price, peak)
        expected = supply_step(
            SCALAR, params, weights, *args, orders[day], spoofed[day], levels[day], action, jitter, noise
        )
        got = fast(*args, day, action, jitter, noise)
        assert type(got) is type(expected)
        assert _bits(list(got)) == _bits(list(expected))
        odd += any(math.isnan(v) for v in got if isinstance(v, float))
    assert 0 < odd < 400  # both finite and NaN outcomes were compared


def _reference_step(env: SupplyChainEnv, action) -> tuple:
    """What the single env's step returns, assembled from the generic pieces the vector env uses."""
    i, k = env.inputs, env._k
    day = env._start + k
    executed = tuple(decode_actions(action, env.action_mode, i.grid).tolist())
    jitter = jitter_of(executed, env._prev)
    out = supply_step(
        SCALAR, i.params, i.weights, env._on_hand, env._pipeline, env._backlog, env._price, env._peak,
        i.orders[day], i.spoofed[day], i.levels[day], executed, jitter, env._noise[k],
    )  # fmt: skip
    info = step_record(out, executed, day, env._start, i.check_rate_list[day], jitter, i.params.scale_units)
    info["step"] = k
    info["region_fill_rates"] = dict(zip(env.regions, out.region_fill_rates, strict=True))
    following = min(day + 1, env.table.days - 1)
    obs = i.observe(
        SCALAR, following, i.spoofed[following], i.levels[following], out.on_hand_units, out.pipeline_units,
        out.backlog_units, out.price_index, executed,
    )  # fmt: skip
    return obs, out.reward, info


@pytest.mark.parametrize("penalty", [True, False])
def test_the_single_envs_step_equals_the_generic_pieces_bit_for_bit(supply_table, penalty):  # noqa: F811
    env = SupplyChainEnv(table=supply_table, no_physics_penalty=not penalty)
    rng = np.random.default_rng(5)
    rewards, resets = [], 0

    def reset(**kwargs) -> None:
        nonlocal resets
        obs, _ = env.reset(**kwargs)
        i = env.inputs
        day = env._start
        expected = i.observe(
            SCALAR, day, i.spoofed[day], i.levels[day], env._on_hand, env._pipeline, env._backlog, 1.0, _INITIAL_PREV
        )
        assert obs.tobytes() == expected.tobytes()
        resets += 1

    reset(seed=1)
    for k in range(60):  # two and a half episodes
        action = rng.random(3, dtype=np.float32) * np.float32(1.4) - np.float32(0.2)
        if k % 4 == 1:
            action[rng.integers(3)] = rng.choice([np.nan, np.inf, -np.inf, -0.0])
        if k % 5 == 2:
            action = action.tolist()  # not a float32 array: decoded by numpy
        expected_obs, expected_reward, expected_info = _reference_step(env, action)
        obs, reward, terminated, truncated, info = env.step(action)
        assert obs.dtype == np.float32 and obs.tobytes() == expected_obs.tobytes()
        assert _bits(reward) == _bits(expected_reward) and not terminated
        assert list(info) == [*STEP_FIELDS, "step", "region_fill_rates"]
        assert _bits(info) == _bits(expected_info)
        rewards.append(reward)
        if truncated:
            reset()
    for day in range(supply_table.days - env.episode_steps + 1):  # honest and spoofed first days
        reset(options={"start_day": day})
    assert resets > 50 and len(set(rewards)) > 50  # the steps differed
