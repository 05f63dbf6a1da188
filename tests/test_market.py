"""Environment and metric formulas (docs/environment.md, docs/metrics.md) against hand-computed values."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from solarchain_eval.config import BenchmarkConfig, MarketConfig
from solarchain_eval.data.table import load_table
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.market import (
    BATCH,
    SCALAR,
    ActionCodec,
    RewardWeights,
    action_jitter_f32,
    market_step,
    numpy_order_sum,
    numpy_order_variance,
)
from solarchain_eval.solar.metrics import action_jitter, episode_metrics, max_drawdown, spatial_fairness_index

F32 = np.float32
CODEC = ActionCodec.from_config(MarketConfig())
WEIGHTS = RewardWeights.from_config(BenchmarkConfig())


def test_decoding_the_corners_of_the_action_box():
    assert CODEC.decode(np.zeros(3, F32)) == (float(F32(0.05)), float(F32(0.2)), 0.0)
    # u = 1: float32 decoding gives α = 0.65000004, which the float32 clip brings to
    # float32(0.65) = 0.64999998 (as the original's np.clip of a float32 scalar does under numpy 2,
    # docs/reproducing.md), and ℓ = 0.94999999; they sum to > 0.98, so both scale by
    # 0.98 / (α + ℓ) in float64; float32 result.
    alpha, ell, burn = CODEC.decode(np.ones(3, F32))
    a32, l32 = float(F32(0.05) + F32(0.6)), float(F32(0.2) + F32(0.75))
    assert a32 == 0.6500000357627869 and float(F32(0.65)) == 0.6499999761581421
    a_clip = float(F32(0.65))
    assert alpha == float(F32(a_clip * (0.98 / (a_clip + l32))))
    assert ell == float(F32(l32 * (0.98 / (a_clip + l32))))
    # At u = (1, 0.25, ·) the float64 clip (to 0.65 itself) would execute ℓ one float32 ulp off the
    # original's 0.36602411 (its env trace has 104 such steps per setting).
    _, ell_quarter, _ = CODEC.decode(np.array([1, 0.25, 0], F32))
    assert ell_quarter == 0.36602410674095154
    l_quarter = float(F32(0.2) + F32(0.75) * F32(0.25))
    assert float(F32(l_quarter * (0.98 / (0.65 + l_quarter)))) == 0.36602407693862915
    assert burn == float(F32(0.2))
    assert abs(alpha - 0.398125) < 1e-7 and abs(ell - 0.581875) < 1e-7
    # NaN -> 0, +inf -> 1, -inf -> 0.
    assert CODEC.decode(np.array([np.nan, np.inf, -np.inf], F32)) == CODEC.decode(np.array([0, 1, 0], F32))


def test_static_policy_executes_the_sanitised_static_action():
    env = SolarChainEnv.__new__(SolarChainEnv)  # decode only needs the codec
    env.action_mode, env.codec = "continuous", CODEC
    executed = env.decode_action(CODEC.encode(0.25, 0.75, 0.02))
    assert executed == pytest.approx((0.245, 0.735, 0.02), abs=1e-7)
    assert executed[0] + executed[1] == pytest.approx(0.98, abs=1e-7)


def test_discrete_grid_is_itertools_product_order():
    grid = CODEC.discrete_grid(5)
    assert grid.shape == (125, 3) and grid.dtype == F32
    assert grid[0].tolist() == [0, 0, 0] and grid[1].tolist() == [0, 0, 0.25] and grid[5].tolist() == [0, 0.25, 0]
    assert grid[25].tolist() == [0.25, 0, 0] and grid[124].tolist() == [1, 1, 1]
    table = CODEC.discrete_table(5)
    assert table[0] == CODEC.decode(grid[0]) and table[124] == CODEC.decode(grid[124])


def test_jitter_is_the_float32_l1_distance():
    a, prev = (F32(0.375), F32(0.5), F32(0.125)), (F32(0.25), F32(0.75), F32(0.02))
    expected = np.abs(np.array(a, F32) - np.array(prev, F32)).sum(dtype=F32)
    assert action_jitter_f32(tuple(map(float, a)), tuple(map(float, prev))) == float(expected)
    assert float(expected) != 0.125 + 0.25 + (0.125 - float(F32(0.02)))  # float32 differs from float64 here


def _one_step(noise: float = 0.001, no_physics: bool = False):
    weights = RewardWeights.from_config(BenchmarkConfig(no_physics_penalty=no_physics))
    action = (0.375, 0.5, 0.125)  # exact in float32
    jitter = action_jitter_f32(action, (float(F32(0.25)), float(F32(0.75)), float(F32(0.02))))
    out = market_step(
        SCALAR, weights, 0.2, 0.05, 0.1, (0.25, 0.75), (1.0, 0.5), 1.0, 1.0, 1.0, 1.0, action, jitter, noise
    )
    return out, jitter


def test_one_step_against_hand_computed_values():
    out, jitter = _one_step()
    # β = 0.875/0.98; A = 0.05β = 25/560 MWh; G_b = 0.2 + A = 137/560; V = A / G_b = 25/137.
    assert out.unsafe_backed_mwh == pytest.approx(25 / 560, rel=1e-13)
    assert out.violation_rate == pytest.approx(25 / 137, rel=1e-13)
    # Q~ = 0.1 · max(0.75, 1 - 0.8·0.125) = 0.09; available = 1 + 0.5 G_b = 1257/1120.
    assert out.matched_mwh == pytest.approx(0.09, rel=1e-13) and out.unmet_mwh == 0.0
    assert out.liquidity == pytest.approx(1257 / 1120 - 0.09, rel=1e-13)
    assert out.peak_liquidity == out.liquidity and out.drawdown == 0.0
    assert out.slippage == pytest.approx(0.09 / (1257 / 1120 + 0.05), rel=1e-13)
    assert out.artificial_liquidity_mwh == pytest.approx(0.5 * 25 / 560, rel=1e-13)
    # Price: r = 0.04 g + 0.03 M + 0.10 b - 0.08 σ - 0.02 α G_b + noise, g = (0.2 - 0.09)/0.09.
    r = 0.04 * (0.11 / 0.09) + 0.03 * 0.09 + 0.10 * 0.125 - 0.08 * out.slippage - 0.02 * (0.375 * 137 / 560) + 0.001
    assert out.token_price == pytest.approx(1 + r, rel=1e-12) and out.token_drawdown == 0.0
    # City rewards: α G_b · share · trust + ℓ · share · 0.01, F = population variance.
    tokens = 0.375 * 137 / 560
    c1, c2 = tokens * 0.25 * 1.0 + 0.5 * 0.25 * 0.01, tokens * 0.75 * 0.5 + 0.5 * 0.75 * 0.01
    assert out.city_rewards == pytest.approx([c1, c2], rel=1e-13)
    assert out.fairness_variance == pytest.approx(((c2 - c1) / 2) ** 2, rel=1e-12)
    expected_reward = 0.09 - 0.25 * jitter - 0.2 * out.fairness_variance - 2.0 * (25 / 137 + 25 / 560)
    assert out.reward == pytest.approx(expected_reward, rel=1e-12)


def test_no_physics_setting_drops_only_the_physics_term():
    main, _ = _one_step()
    ablation, _ = _one_step(no_physics=True)
    assert ablation.reward - main.reward == pytest.approx(2.0 * (25 / 137 + 25 / 560), rel=1e-12)
    assert ablation.violation_rate == main.violation_rate and ablation.unsafe_backed_mwh == main.unsafe_backed_mwh


def test_unmet_demand_drawdown_and_price_clip():
    weights = WEIGHTS
    action = (0.05, 0.2, 0.0)
    # Liquidity 0.1 + 0.2·0.1 = 0.12 cannot serve demand 2.0: unmet 1.88, pool emptied, D = 1.
    out = market_step(SCALAR, weights, 0.1, 0.0, 2.0, (1.0,), (1.0,), 0.1, 1.0, 1.0, 1.0, action, 0.0, 0.0)
    assert out.matched_mwh == pytest.approx(0.12) and out.unmet_mwh == pytest.approx(1.88)
    assert out.liquidity == 0.0 and out.drawdown == 1.0
    # The price return is clipped at -0.35 and the price floored at 0.05.
    assert out.token_price == pytest.approx(0.65)
    low = market_step(SCALAR, weights, 0.1, 0.0, 2.0, (1.0,), (1.0,), 0.1, 1.0, 0.06, 1.0, action, 0.0, 0.0)
    assert low.token_price == 0.05


def test_batch_step_equals_scalar_step_elementwise():
    rng = np.random.default_rng(3)
    n, cities = 64, 5
    args = [rng.random(n) * s for s in (0.5, 0.1, 0.2)]
    share = rng.dirichlet(np.ones(cities), size=n).T.copy()
    trust = rng.random((cities, n))
    state = [rng.random(n) + 0.5 for _ in range(4)]
    actions = CODEC.decode_batch(rng.random((n, 3), dtype=F32)).astype(np.float64)
    jitter, noise = rng.random(n), rng.normal(0, 0.004, n)
    batch = market_step(BATCH, WEIGHTS, *args, share, trust, *state, tuple(actions), jitter, noise)
    for i in range(n):
        single = market_step(
            SCALAR,
            WEIGHTS,
            *(a[i] for a in args),
            tuple(share[:, i]),
            tuple(trust[:, i]),
            *(s[i] for s in state),
            tuple(actions[:, i]),
            jitter[i],
            noise[i],
        )
        for field in single._fields:
            if field == "city_rewards":
                assert list(batch.city_rewards[:, i]) == single.city_rewards
            else:
                assert getattr(batch, field)[i] == getattr(single, field), field


@pytest.mark.parametrize("n", [1, 2, 5, 7, 8, 9, 15, 16, 17, 64, 127, 128, 129, 300, 1000])
def test_numpy_order_sum_and_variance_match_numpy_bit_for_bit(n):
    values = np.random.default_rng(n).normal(size=n) * 10.0 ** np.random.default_rng(n + 1).uniform(-6, 6, n)
    assert numpy_order_sum(list(values)) == np.add.reduce(values)
    assert numpy_order_variance(list(values)) == np.var(values)


def test_episode_metric_helpers_on_hand_computed_series():
    # Drawdown: peaks exclude the initial value; 1 - 1.5/2.0 = 0.25 is the largest fall.
    assert max_drawdown(np.array([1.2, 2.0, 1.5, 1.9])) == pytest.approx(0.25)
    assert max_drawdown(np.array([0.5, 0.4])) == pytest.approx(0.2)  # the initial 1.0 is not a peak
    actions = np.array([[0.1, 0.2, 0.0], [0.2, 0.2, 0.1], [0.2, 0.5, 0.1]], F32)
    assert action_jitter(actions) == pytest.approx(((0.1 + 0.1) + 0.3) / 2, rel=1e-6)
    assert spatial_fairness_index(np.array([1.0, 3.0])) == pytest.approx(1.0 / 2.0)
    metrics = episode_metrics(
        reward=np.array([1.0, -2.0]),
        matched_mwh=np.array([0.5, 0.25]),
        violation_rate=np.array([0.2, 0.4]),
        liquidity=np.array([1.0, 0.5]),
        token_price=np.array([1.0, 1.1]),
        actions=actions[:2],
        slippage=np.array([0.1, 0.3]),
        artificial_liquidity_mwh=np.array([0.01, 0.02]),
        city_totals=np.array([1.0, 3.0]),
    )
    assert metrics == pytest.approx(
        {
            "cumulative_reward": -1.0,
            "episode_volume": 0.75,
            "physics_violation_rate": 0.3,
            "max_drawdown": 0.5,
            "max_token_drawdown": 0.0,
            "action_jitter": 0.2,
            "mean_slippage": 0.2,
            "spatial_fairness_index": 0.5,
            "artificial_liquidity_MWh": 0.03,
            "final_liquidity": 0.5,
            "final_token_price": 1.1,
        },
        rel=1e-6,
    )


def test_hourly_table_and_observation_against_the_csvs(published_dir):
    """The hourly table (docs/dataset.md#hourly-table) recomputed independently from the raw CSVs for a daytime hour."""
    gen = pd.read_csv(published_dir / "spatiotemporal_generation.csv")
    trades = pd.read_csv(published_dir / "p2p_trades.csv")
    market = pd.read_csv(published_dir / "market_liquidity.csv")
    stamp, hour = "2026-04-02T11:00:00+08:00", 35
    rows = gen[gen["timestamp"] == stamp]
    verified = rows.loc[rows["verification_status"] == "verified", "P_reported_W"].sum() / 1e6
    excess = (rows["P_reported_W"] - rows["P_max_W"]).clip(lower=0)
    violation = (excess > 1e-6) | rows["fdia_detected"]
    demand = trades.loc[trades["timestamp"] == stamp, "energy_purchased_MW"].sum()
    table = load_table(published_dir)
    assert table.verified_mwh[hour] == pytest.approx(verified, rel=1e-12)
    assert table.reported_mwh[hour] == pytest.approx(rows["P_reported_W"].sum() / 1e6, rel=1e-12)
    assert table.raw_violation_rate[hour] == violation.mean()
    assert table.demand_mwh[hour] == pytest.approx(demand, rel=1e-12) and demand > 0
    assert table.static_slippage[hour] == market.loc[market["timestamp"] == stamp, "slippage_solarchain_pct"].item()
    env = SolarChainEnv(published_dir)
    obs, _ = env.reset(options={"start_hour": 24})
    for _ in range(11):
        obs, *_ = env.step(env.codec.encode(0.25, 0.75, 0.02))
    expected = [
        np.sin(2 * np.pi * 11 / 24),
        np.cos(2 * np.pi * 11 / 24),
        verified,
        rows["P_reported_W"].sum() / 1e6,
        rows["P_max_W"].sum() / 1e6,
        (verified - demand) / demand,
        env._liquidity,
        env._price,
        violation.mean(),
        table.static_slippage[hour],
        0.245,
        0.735,
    ]
    assert obs == pytest.approx(np.array(expected, dtype=F32), rel=1e-6)


@pytest.mark.parametrize("cities", [1, 3, 5, 7, 8, 9, 12])
def test_batch_city_variance_equals_numpy_var_per_sub_env(cities):
    values = np.random.default_rng(cities).normal(size=(cities, 257)) * 10.0 ** np.random.default_rng(1).uniform(
        -5, 5, (cities, 257)
    )
    expected = np.array([np.var(values[:, i]) for i in range(values.shape[1])])
    assert np.array_equal(BATCH.city_variance(values), expected)
