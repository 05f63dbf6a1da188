"""The task seam: the interface, the registry, the solar market as its first task, and a second
market defined only under tests/ (toy_task.py) driven by the generic rollout."""

from __future__ import annotations

import numpy as np
import pytest

from solarchain_eval.evaluation.rollout import STEP_FIELDS, run_policy
from solarchain_eval.market.baselines import make_baseline
from solarchain_eval.records_schema import METRIC_NAMES, Column
from solarchain_eval.solar.metrics import episode_metrics
from solarchain_eval.tasks import (
    DIMENSIONS,
    MetricSpec,
    Task,
    UnknownTaskError,
    get_task,
    metric_names,
    metrics_of,
    register_task,
    task_names,
    unregister_task,
)
from toy_task import TOY_TASK, SteadyPolicy

SEED = 20260511


def test_the_default_task_is_the_solar_market_and_declares_every_metric_column():
    task = get_task()
    assert task.name == "solar" and task.env_id == "SolarChainEval-v0" and isinstance(task, Task)
    assert metric_names(task) == METRIC_NAMES  # the declaration is metrics.csv's column order
    assert task.step_fields == STEP_FIELDS
    assert [lever.name for lever in task.levers] == ["reward_ratio", "liquidity_ratio", "burn_rate"]
    assert {m.dimension for m in task.metrics} == set(DIMENSIONS) - {"auditability"}  # the layer adds that one
    assert [m.name for m in metrics_of(task, "safety")] == ["physics_violation_rate", "artificial_liquidity_MWh"]
    assert sorted(task.baselines()) == ["myopic", "random", "static"]


def test_the_solar_tasks_episode_metrics_are_the_markets_own(tiny_dataset):
    task = get_task()
    from solarchain_eval.config import BenchmarkConfig

    config = BenchmarkConfig()
    env = task.make_env(config, task.load_data(tiny_dataset))
    (result,) = run_policy(env, make_baseline("myopic", config.market), setting="main", run_seeds=[SEED], episodes=1)
    steps = result.steps
    expected = episode_metrics(
        reward=np.asarray(steps["reward"]),
        matched_mwh=np.asarray(steps["matched_energy_MWh"]),
        violation_rate=np.asarray(steps["physics_violation_rate"]),
        liquidity=np.asarray(steps["liquidity"]),
        token_price=np.asarray(steps["token_price"]),
        actions=np.column_stack([np.float32(steps[c]) for c in ("reward_ratio", "liquidity_ratio", "burn_rate")]),
        slippage=np.asarray(steps["slippage"]),
        artificial_liquidity_mwh=np.asarray(steps["artificial_liquidity_MWh"]),
        city_totals=np.asarray(list(env.city_totals.values())),
    )
    assert result.metrics == expected and list(result.metrics) == list(METRIC_NAMES)
    assert len(result.city_rewards[0]) == len(env.city_totals)


def test_a_second_task_runs_through_the_generic_rollout():
    register_task(TOY_TASK)
    try:
        task = get_task("toy-stock")
        assert task is TOY_TASK and "toy-stock" in task_names()
        env = task.make_env(None, task.load_data(None))
        results = list(
            run_policy(env, SteadyPolicy(), setting="main", run_seeds=[SEED, SEED + 1], episodes=2, task=task)
        )
        assert [(r.run_seed, r.episode) for r in results] == [(SEED, 0), (SEED, 1), (SEED + 1, 0), (SEED + 1, 1)]
        first = results[0]
        assert list(first.steps) == list(task.step_fields) and first.n_steps == 12
        assert list(first.metrics) == ["total_reward", "shortfall_units", "stock_swing"]
        assert first.metrics["total_reward"] == pytest.approx(float(np.sum(first.steps["reward"])))
        assert first.metrics != results[1].metrics  # each episode its own seeded demand
        assert first.city_rewards == [()] * 12
    finally:
        unregister_task("toy-stock")
    with pytest.raises(UnknownTaskError, match=r"unknown task 'toy-stock' \(available: solar"):
        get_task("toy-stock")


def test_the_registry_refuses_what_is_not_a_task():
    with pytest.raises(TypeError, match="does not implement the Task interface"):
        register_task(object())
    bad = type(TOY_TASK)()
    bad.name = "Has Spaces"
    with pytest.raises(ValueError, match="lowercase letters"):
        register_task(bad)
    with pytest.raises(ValueError, match="dimension 'speed'"):
        MetricSpec(Column("x", "–", "x"), "speed", "higher")
    with pytest.raises(ValueError, match="direction 'up'"):
        MetricSpec(Column("x", "–", "x"), "utility", "up")
