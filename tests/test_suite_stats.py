"""The suite's aggregates equal rliable's definitions, re-derived here by hand on fixed matrices
(rliable is not a dependency: its functions are written out in evaluation/suite_stats.py)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from solarchain_eval.evaluation import suite_stats as st

#: 4 runs x 3 tasks, every value distinct.
M = np.array(
    [
        [0.10, 1.40, -0.30],
        [0.90, 0.20, 0.50],
        [0.40, 1.10, 0.05],
        [1.70, 0.60, 0.80],
    ]
)


def test_iqm_is_the_mean_of_the_middle_half_of_every_score():
    # 12 scores: rliable's trim_mean(0.25, axis=None) drops the 3 lowest and the 3 highest
    middle = np.sort(M.ravel())[3:9]
    assert st.aggregate_iqm(M) == pytest.approx(middle.mean(), abs=1e-12)
    assert st.aggregate_iqm(M) == pytest.approx((0.2 + 0.4 + 0.5 + 0.6 + 0.8 + 0.9) / 6, abs=1e-12)


def test_iqm_drops_whole_scores_not_fractions_of_them():
    # 10 scores: int(0.25 * 10) = 2 dropped at each end, no fractional weights (the leaderboard's IQM
    # weights the boundary scores fractionally and would give another value here)
    scores = np.arange(10, dtype=float).reshape(5, 2) ** 2
    assert st.aggregate_iqm(scores) == pytest.approx(np.mean([4, 9, 16, 25, 36, 49]), abs=1e-12)


def test_mean_and_median_are_of_the_per_task_means():
    task_means = [(0.1 + 0.9 + 0.4 + 1.7) / 4, (1.4 + 0.2 + 1.1 + 0.6) / 4, (-0.3 + 0.5 + 0.05 + 0.8) / 4]
    assert st.aggregate_mean(M) == pytest.approx(sum(task_means) / 3, abs=1e-12)
    assert st.aggregate_median(M) == pytest.approx(sorted(task_means)[1], abs=1e-12)
    unbalanced = np.array([[0.0, 10.0], [0.0, 10.0], [3.0, 10.0]])
    assert st.aggregate_median(unbalanced) == pytest.approx((1.0 + 10.0) / 2)


def test_optimality_gap_with_gamma_one():
    clipped = [min(v, 1.0) for v in M.ravel()]
    assert st.aggregate_optimality_gap(M) == pytest.approx(1.0 - sum(clipped) / 12, abs=1e-12)
    assert st.aggregate_optimality_gap(np.full((2, 2), 3.0)) == 0.0
    assert st.aggregate_optimality_gap(M, gamma=0.5) == pytest.approx(
        0.5 - np.mean([min(v, 0.5) for v in M.ravel()]), abs=1e-12
    )


def _poi_by_hand(x: np.ndarray, y: np.ndarray) -> float:
    per_task = []
    for task in range(x.shape[1]):
        pairs = list(itertools.product(x[:, task], y[:, task]))
        per_task.append(sum(1.0 if a > b else 0.5 if a == b else 0.0 for a, b in pairs) / len(pairs))
    return float(np.mean(per_task))


def test_probability_of_improvement_is_the_normalised_mann_whitney_statistic():
    y = np.array([[0.4, 1.0, 0.0], [0.2, 0.6, 0.9], [0.1, 0.6, 0.2]])  # 3 runs against M's 4; ties with M's 0.4, 0.6
    assert st.probability_of_improvement(M, y) == pytest.approx(_poi_by_hand(M, y), abs=1e-12)
    assert st.probability_of_improvement(M, y) + st.probability_of_improvement(y, M) == pytest.approx(1.0)
    assert st.probability_of_improvement(M, M) == 0.5
    assert st.probability_of_improvement(M + 10, M) == 1.0


def test_the_performance_profile_counts_scores_strictly_above_each_threshold():
    taus = np.array([-1.0, 0.0, 0.5, 0.6, 2.0])
    expected = [sum(v > t for v in M.ravel()) / 12 for t in taus]
    assert st.score_distribution(M, taus).tolist() == pytest.approx(expected)
    assert st.score_distribution(M, [0.6]).tolist() == [5 / 12]  # 0.6 itself is not above 0.6


def test_the_bootstrap_resamples_runs_within_each_task():
    seen = []

    def spy(sample: np.ndarray) -> float:
        seen.append(sample.copy())
        return float(sample.mean())

    st.stratified_bootstrap_interval(M, spy, reps=50, seed=3)
    assert len(seen) == 50
    for sample in seen:
        assert sample.shape == M.shape
        for task in range(M.shape[1]):  # a column draws only from its own task's runs
            assert set(sample[:, task]) <= set(M[:, task])
    assert any(len(set(sample[:, 0])) < 4 for sample in seen)  # with replacement


def test_a_task_constant_matrix_gives_a_zero_width_interval():
    # stratified by task: a resample keeps each task's runs, so the mean never moves; mixing tasks would
    constant = np.tile([0.0, 1.0, 5.0], (6, 1))
    assert st.stratified_bootstrap_interval(constant, st.aggregate_mean, reps=200) == pytest.approx((2.0, 2.0))


def test_the_bootstrap_is_reproducible_and_percentile():
    rng = np.random.default_rng(7)
    scores = rng.normal(size=(20, 4))
    first = st.stratified_bootstrap_interval(scores, st.aggregate_iqm, reps=400, seed=11)
    assert first == st.stratified_bootstrap_interval(scores, st.aggregate_iqm, reps=400, seed=11)
    assert first != st.stratified_bootstrap_interval(scores, st.aggregate_iqm, reps=400, seed=12)
    # the percentile interval of the same resamples, re-derived
    draws = np.random.default_rng(11)
    estimates = [st.aggregate_iqm(scores[draws.integers(0, 20, size=(20, 4)), np.arange(4)]) for _ in range(400)]
    assert first == pytest.approx(tuple(np.percentile(estimates, [2.5, 97.5])), abs=1e-12)
    assert first[0] < st.aggregate_iqm(scores) < first[1]


def test_the_aggregate_table_holds_every_aggregate_and_its_interval():
    rows = st.aggregate_table({"a": M, "b": M + 1}, reps=100, seed=0)
    assert [r["policy"] for r in rows] == ["a", "b"]
    for name in st.AGGREGATE_NAMES:
        assert rows[0][name] == pytest.approx(st.AGGREGATES[name](M))
        assert rows[0][f"{name}_low"] <= rows[0][name] <= rows[0][f"{name}_high"]
    assert rows[1]["iqm"] == pytest.approx(rows[0]["iqm"] + 1)
    pairs = st.improvement_table({"a": M, "b": M + 1})
    assert pairs == [{"policy": "a", "over": "b", "probability": pytest.approx(_poi_by_hand(M, M + 1))}, {
        "policy": "b", "over": "a", "probability": pytest.approx(_poi_by_hand(M + 1, M))}]  # fmt: skip
