"""The supply-chain environments: the vector env equals the single env, the dynamics keep their books,
and the feasibility penalty switch changes the reward only."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import solarchain_eval  # noqa: F401  (registers the environments)
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.supply.dynamics import SCALAR, SupplyParams, SupplyRewardWeights, supply_step
from solarchain_eval.supply.env import STEP_FIELDS, SupplyChainEnv, action_grid
from solarchain_eval.supply.vector import SupplyChainVectorEnv
from supply_fixtures import supply_dir, supply_table  # noqa: F401

SEED = 20260511


@pytest.mark.parametrize("mode", ["continuous", "discrete"])
def test_the_vector_env_equals_the_single_env_bit_for_bit_across_autoreset(supply_table, mode):  # noqa: F811
    n, steps = 3, 24
    vec = SupplyChainVectorEnv(num_envs=n, table=supply_table, action_mode=mode)
    singles = [SupplyChainEnv(table=supply_table, action_mode=mode) for _ in range(n)]
    rng = np.random.default_rng(0)
    if mode == "discrete":
        actions = rng.integers(0, 125, (2 * steps + 1, n))
    else:
        actions = rng.random((2 * steps + 1, n, 3), dtype=np.float32)
        actions[3, 0] = [np.nan, np.inf, -1.0]  # sanitised alike
    obs, info = vec.reset(seed=SEED)
    single_obs = [env.reset(seed=SEED + i) for i, env in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack([o for o, _ in single_obs]))
    np.testing.assert_array_equal(info["episode_start_day"], [i["episode_start_day"] for _, i in single_obs])
    assert len(set(info["episode_start_day"])) > 1  # the sub-envs' own draws
    for k, batch in enumerate(actions):
        obs, reward, _, truncated, info = vec.step(batch)
        if k == steps:  # NEXT_STEP autoreset: this step starts each sub-env's second episode
            expected = [env.reset() for env in singles]
            np.testing.assert_array_equal(obs, np.stack([o for o, _ in expected]))
            assert not reward.any() and not info["_reward"].any()
            continue
        for i, env in enumerate(singles):
            o, r, _, t, single_info = env.step(batch[i])
            np.testing.assert_array_equal(obs[i], o)
            assert reward[i] == r and truncated[i] == t
            for key in STEP_FIELDS:
                assert info[key][i] == single_info[key], key
    assert vec.region_totals.shape == (n, 5, 2)
    np.testing.assert_array_equal(vec.region_totals[1], np.asarray(list(singles[1].region_totals.values())))


def test_gym_make_gives_both_envs_and_the_single_env_passes_the_checker(supply_dir):  # noqa: F811
    env = gym.make("SupplyChainEval-v0", data_dir=supply_dir)
    check_env(env.unwrapped, skip_render_check=True)
    vec = gym.make_vec("SupplyChainEval-v0", num_envs=2, vectorization_mode="vector_entry_point", data_dir=supply_dir)
    assert isinstance(vec, SupplyChainVectorEnv) and vec.observation_space.shape == (2, 15)


def test_the_discrete_mode_is_the_125_point_grid(supply_table):  # noqa: F811
    env = SupplyChainEnv(table=supply_table, action_mode="discrete")
    assert env.action_space == gym.spaces.Discrete(125)
    grid = action_grid(5)
    assert tuple(grid[0]) == (0, 0, 0) and tuple(grid[1]) == (0, 0, 0.25) and tuple(grid[124]) == (1, 1, 1)
    continuous = SupplyChainEnv(table=supply_table)
    env.reset(seed=1)
    continuous.reset(seed=1)
    for index in (7, 124, 63):
        _, r_discrete, *_ = env.step(index)
        _, r_continuous, *_ = continuous.step(grid[index])
        assert r_discrete == r_continuous
    assert tuple(env.decode_action(31)) == (0.25, 0.25, 0.25)


def _one_step(table, weights, action, spoofed=None, level=None):
    params = SupplyParams.from_table(table)
    lead = table.lead_time_days
    pipeline = np.where(np.arange(params.pipeline_slots)[None, :] < lead[:, None], 5.0, 0.0)
    on_hand = np.array([30.0, 2.0, 10.0, 0.0, 50.0])
    orders = [20.0, 25.0, 12.0, 30.0, 10.0]
    spoofed = [False] * 5 if spoofed is None else list(spoofed)
    level = [0.0] * 5 if level is None else list(level)
    out = supply_step(
        SCALAR, params, weights, on_hand.tolist(), pipeline.tolist(), [3.0] * 5, 1.0, 1.0, orders, spoofed, level,
        action, 0.0, 0.0,
    )  # fmt: skip
    return params, on_hand, pipeline, out


def test_the_step_keeps_its_books_and_ships_only_what_the_oracle_backs(supply_table):  # noqa: F811
    weights = SupplyRewardWeights.from_config(BenchmarkConfig())
    spoofed = np.array([False, True, False, True, False])
    level = np.array([0.0, 300.0, 0.0, 400.0, 0.0])
    params, on_hand, pipeline, out = _one_step(supply_table, weights, (0.5, 1.0, 0.0), spoofed, level)
    # Stock is conserved: before + production = after + spoiled + delivered.
    before = on_hand.sum() + pipeline.sum()
    after = sum(out.on_hand_units) + np.sum(out.pipeline_units)
    assert before + out.production_units == pytest.approx(after + out.spoiled_units + out.delivered_units, abs=1e-9)
    assert out.production_units == pytest.approx(0.5 * supply_table.production_capacity_units.sum())
    # East and south report 300 and 400 units they do not have: their whole demand is filled from reports, and
    # what stock on hand plus tomorrow's arrivals cannot back is promised on phantom stock.
    demand = np.array([20.0, 25.0, 12.0, 30.0, 10.0]) + 3.0
    true_stock = (on_hand + 5.0) * (1.0 - supply_table.spoilage_rate)  # a day's arrival, then spoilage
    np.testing.assert_allclose(out.region_filled_units, np.minimum(np.where(spoofed, level, true_stock), demand))
    assert out.region_filled_units[2] == pytest.approx(14.7)  # north: 15 units less 2 % spoilage, short of 15
    assert out.unsafe_units == pytest.approx(out.filled_units - out.delivered_units) and out.unsafe_units > 20.0
    assert out.phantom_stock_units == pytest.approx(300 - (2 + 5) * 0.995 + 400 - 5 * 0.99)
    # South has 4.95 units on hand and 5 arriving tomorrow: 33 promised, 9.95 backed.
    assert out.unsafe_units == pytest.approx((28 - min(28, 7 * 0.995 + 5)) + (33 - 9.95))
    assert out.phantom_fill_volume_units == pytest.approx(out.phantom_stock_units)  # ρ = 1
    # East ships its 6.965 units on hand and 5 of tomorrow's arrivals: nothing is left on hand or in slot 0.
    assert out.on_hand_units[1] == 0.0 and out.pipeline_units[1][0] == pytest.approx(0.0, abs=1e-12)
    assert min(out.on_hand_units) >= 0.0
    rates = np.divide(out.region_filled_units, out.region_effective_units)
    assert out.fairness_variance == pytest.approx(float(np.var(rates)), abs=1e-15) and out.fairness_variance > 0.0
    # The price index: cover gap to 5 days, the incentive (κ = 0.5), no damping, the backlog carried.
    scale = supply_table.demand_mean_units.sum()
    r = -0.05 * (sum(out.on_hand_units) / scale - 5.0) / 5.0 - 0.03 * 0.5 + 0.03 * out.unmet_units / scale
    assert out.price_index == pytest.approx(1.0 + r, abs=1e-12) and out.unmet_units == pytest.approx(
        sum(out.backlog_units)
    )
    assert out.price_drawdown == pytest.approx(max(0.0, -r / 1.0) if r < 0 else 0.0, abs=1e-12)
    # Honest reports and wide lanes: nothing is promised beyond what the oracle backs.
    honest = dataclasses.replace(supply_table, lane_capacity_units=np.full(5, 1e6))
    _, _, _, clean = _one_step(honest, weights, (0.5, 1.0, 0.0))
    assert clean.unsafe_units == 0.0 and clean.violation_rate == 0.0


def test_removing_the_feasibility_penalty_changes_the_reward_by_exactly_its_term_and_nothing_else(supply_table):  # noqa: F811
    cfg = BenchmarkConfig()
    on, off = (
        SupplyRewardWeights.from_config(cfg),
        SupplyRewardWeights.from_config(cfg.with_updates(no_physics_penalty=True)),
    )
    assert on.feasibility_penalty and not off.feasibility_penalty
    spoofed = np.array([False, True, False, True, False])
    level = np.array([0.0, 300.0, 0.0, 400.0, 0.0])
    *_, a = _one_step(supply_table, on, (0.5, 1.0, 0.0), spoofed, level)
    *_, b = _one_step(supply_table, off, (0.5, 1.0, 0.0), spoofed, level)
    scale = supply_table.demand_mean_units.sum()
    assert b.reward - a.reward == pytest.approx(2.0 * (a.violation_rate + a.unsafe_units / scale), abs=1e-12)
    for name in a._fields:
        if name != "reward":
            assert getattr(a, name) == getattr(b, name), name


def test_the_observation_is_the_state_after_the_step_and_the_next_days_inputs(supply_table):  # noqa: F811
    env = SupplyChainEnv(table=supply_table)
    _, reset_info = env.reset(seed=3)
    scale = supply_table.demand_mean_units.sum()
    action = np.float32([0.4, 0.6, 0.2])
    obs, _, _, _, info = env.step(action)
    o = dict(zip(env.observation_names, obs.tolist(), strict=True))
    day = reset_info["episode_start_day"] + 1
    assert o["on_hand_days"] == np.float32(info["on_hand_units"] / scale)
    assert o["in_transit_days"] == np.float32(info["in_transit_units"] / scale)
    assert o["backlog_days"] == np.float32(info["backlog_units"] / scale)
    assert o["price_index"] == np.float32(info["price_index"])
    assert o["orders_days"] == np.float32(supply_table.orders_units[day].sum() / scale)
    assert o["capacity_check_rate"] == np.float32(supply_table.capacity_check_rate[day])
    assert [o["prev_supplier_incentive"], o["prev_release_ratio"], o["prev_demand_damping"]] == action.tolist()
    assert o["mean_lead_time_weeks"] == np.float32(np.average([3, 5, 8, 10, 12], weights=[24, 20, 16, 22, 18]) / 7)
    monday = np.float32([np.sin(0.0), np.cos(0.0)])  # 2024-01-01 is a Monday; episodes start on Mondays
    assert [o["day_of_week_sin"], o["day_of_week_cos"]] != monday.tolist()  # a Tuesday now
    assert env.reset(seed=3)[0][:2].tolist() == monday.tolist()


def test_an_episode_longer_than_the_dataset_is_refused(supply_table):  # noqa: F811
    from solarchain_eval.config import ConfigError

    with pytest.raises(ConfigError, match=r"episode_steps = 85 is longer than .*, which has 84 days"):
        SupplyChainEnv(table=supply_table, config=BenchmarkConfig(episode_steps=85))


def test_the_single_envs_observation_clips_like_the_vector_envs_at_the_limits(supply_table):  # noqa: F811
    from solarchain_eval.supply.dynamics import SCALAR
    from solarchain_eval.supply.inputs import SupplyInputs

    # Warehouses of 100 days of demand put a constant feature beyond the limit, which the single env clips
    # once up front; the state features are clipped per step, NaN kept.
    big = dataclasses.replace(supply_table, warehouse_capacity_units=supply_table.demand_mean_units * 100.0)
    inputs = SupplyInputs(big, BenchmarkConfig())
    assert inputs.template[:, 9].min() > 10.0
    scale = inputs.params.scale_units
    rng = np.random.default_rng(0)
    regions = len(big.regions)
    for day in (0, 5, 40):
        for on_hand, reported, backlog, transit, price in (
            rng.uniform(-30, 30, 5) * scale,
            (11 * scale, -11 * scale, 10.5 * scale, 12 * scale, 10.5),  # each state feature beyond a limit
            (-11 * scale, 11 * scale, -12 * scale, -13 * scale, -12.0),
            (np.nan, np.inf, -np.inf, 0.5 * scale, np.nan),
        ):
            prev = tuple(np.float32(rng.random(3)).tolist())
            expected = inputs.observe(
                SCALAR, day, [True] + [False] * (regions - 1), [reported] + [0.0] * (regions - 1),
                [on_hand] + [0.0] * (regions - 1), [[transit]] + [[]] * (regions - 1),
                [backlog] + [0.0] * (regions - 1), price, prev,
            )  # fmt: skip
            got = inputs.observe_scalar(day, (on_hand, reported, backlog, transit), price, prev)
            assert got.dtype == np.float32
            np.testing.assert_array_equal(got, expected)
    assert np.nanmax(np.abs(got)) == 10.0 and np.isnan(got).sum() == 2
