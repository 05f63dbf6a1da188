"""Report statistics against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from solarchain_eval.report import statistics as S


def test_mean_std_is_the_sample_std():
    mean, std = S.mean_std([1.0, 2.0, 3.0, 4.0])
    assert mean == 2.5
    assert std == pytest.approx(math.sqrt(5.0 / 3.0), rel=1e-15)  # Σ(x - 2.5)² = 5, ddof = 1
    assert math.isnan(S.mean_std([7.0])[1])


def test_t_interval_by_hand():
    interval = S.t_interval([1.0, 2.0, 3.0])  # mean 2, sd 1, t(0.975, 2) = 4.302653
    assert interval.estimate == 2.0
    assert interval.high - 2.0 == pytest.approx(4.302652729911275 / math.sqrt(3.0), rel=1e-9)
    assert interval.low == pytest.approx(2.0 - 4.302652729911275 / math.sqrt(3.0), rel=1e-9)


def test_welch_by_hand():
    # a: mean 2, var 1, n 3; b: mean 5, var 20/3, n 4 -> se² = 1/3 + 5/3 = 2
    result = S.welch_test([1, 2, 3], [2, 4, 6, 8])
    assert result.t_statistic == pytest.approx(-3.0 / math.sqrt(2.0), rel=1e-12)
    dof = 4.0 / ((1 / 3) ** 2 / 2 + (5 / 3) ** 2 / 3)
    assert result.dof == pytest.approx(dof, rel=1e-12)
    assert result.p_value == pytest.approx(2 * stats.t.sf(3.0 / math.sqrt(2.0), dof), rel=1e-10)
    assert (result.n_a, result.n_b, result.mean_a, result.mean_b) == (3, 4, 2.0, 5.0)


def _rollouts(setting, rows):
    return pd.DataFrame(
        [
            {
                "setting": setting,
                "policy": p,
                "run_seed": s,
                "episode": e,
                "episode_seed": s + e,
                "start_hour": 24 * e,
                "r": r,
            }
            for p, s, e, r in rows
        ]
    )


def test_paired_deltas_match_on_policy_seed_and_episode():
    base = _rollouts("main", [("ppo", 1, 0, 1.0), ("ppo", 1, 1, 2.0), ("sac", 1, 0, 5.0), ("ppo", 2, 0, 0.5)])
    # treated rows in another order, one rollout without partner on each side
    treated = _rollouts("no_physics", [("sac", 1, 0, 4.0), ("ppo", 1, 1, 2.5), ("ppo", 1, 0, 3.0), ("dqn", 1, 0, 9.0)])
    result = S.paired_deltas(pd.concat([base, treated]), "main", "no_physics", ["r"])
    got = {(r.policy, r.run_seed, r.episode): r.r for r in result.frame.itertuples()}
    assert got == {("ppo", 1, 0): 2.0, ("ppo", 1, 1): 0.5, ("sac", 1, 0): -1.0}
    assert result.unmatched == 2


def test_paired_deltas_refuse_different_episode_seeds():
    base = _rollouts("main", [("ppo", 1, 0, 1.0)])
    treated = _rollouts("llm", [("ppo", 1, 0, 2.0)]).assign(episode_seed=99)
    with pytest.raises(ValueError, match="episode seed"):
        S.paired_deltas(pd.concat([base, treated]), "main", "llm", ["r"])


def test_interquartile_mean_by_hand():
    assert S.interquartile_mean(np.arange(1.0, 9.0)) == 4.5  # mean of 3, 4, 5, 6
    # n = 6: middle mass [1.5, 4.5] takes half of 2, all of 3 and 4, half of 5
    assert S.interquartile_mean([6.0, 1.0, 5.0, 2.0, 4.0, 3.0]) == pytest.approx((1.0 + 3 + 4 + 2.5) / 3.0)
    # weights act as multiplicities: [1, 1, 1, 10] -> mass [1, 3] lies on the 1s
    assert S.interquartile_mean([1.0, 10.0], np.array([3.0, 1.0])) == 1.0
    assert S.interquartile_mean(np.arange(90.0)) == pytest.approx(
        stats.trim_mean(np.arange(90.0), 0.25) + 0.0, abs=1e-12
    )


def test_probability_of_improvement_by_hand():
    assert S.probability_of_improvement([1, 2, 3], [2, 2]) == 0.5  # (0+0 + .5+.5 + 1+1) / 6
    assert S.probability_of_improvement([3, 4], [1, 2]) == 1.0
    weighted = S.probability_of_improvement([1, 3], [2], np.array([[3.0, 1.0]]), np.array([[1.0]]))
    assert weighted[0] == 0.25  # three copies of 1 lose, one 3 wins


def test_cluster_bootstrap_is_seeded_and_respects_clusters():
    rng = np.random.default_rng(0)
    day_effect = rng.normal(0, 1, 6)
    values = np.repeat(day_effect, 15) + rng.normal(0, 0.05, 90)  # 90 rows, 6 independent days
    days = np.repeat(np.arange(6), 15)
    clustered = S.bootstrap_mean(values, days, n_resamples=1000, seed=3)
    assert clustered == S.bootstrap_mean(values, days, n_resamples=1000, seed=3)
    assert clustered.estimate == pytest.approx(values.mean(), rel=1e-12)
    naive = S.bootstrap_mean(values, np.arange(90), n_resamples=1000, seed=3)
    # treating the 90 rows as independent understates the uncertainty several-fold
    assert (clustered.high - clustered.low) > 2.5 * (naive.high - naive.low)
    single = S.bootstrap_mean(values, np.zeros(90))
    assert math.isnan(single.low) and math.isnan(single.high)


def test_bootstrap_difference_resamples_shared_days_jointly():
    days = np.repeat(np.arange(8), 5)
    rng = np.random.default_rng(1)
    shared = np.repeat(rng.normal(0, 3, 8), 5)
    a, b = shared + 1.0, shared  # the same days, a constant improvement of 1
    diff = S.bootstrap_mean_difference(a, days, b, days, n_resamples=500)
    assert diff.estimate == pytest.approx(1.0)
    assert diff.low == pytest.approx(1.0) and diff.high == pytest.approx(1.0)
    poi = S.bootstrap_probability_of_improvement(a, days, b, days, n_resamples=500)
    assert 0.5 < poi.estimate < 1.0 and poi.low <= poi.estimate <= poi.high


def test_paired_cluster_test_uses_day_means():
    a = [1.0, 1.2, 2.0, 2.2, 3.0, 3.4]
    b = [0.0, 0.0, 1.5, 1.5, 2.0, 2.0]
    days = [0, 0, 1, 1, 2, 2]
    p, n = S.paired_cluster_test(a, days, b, days)
    expected = stats.ttest_rel([1.1, 2.1, 3.2], [0.0, 1.5, 2.0]).pvalue
    assert n == 3 and p == pytest.approx(expected)
