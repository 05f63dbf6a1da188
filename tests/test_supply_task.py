"""The supply-chain market as a task: found by name, driven by the generic rollout like any task."""

from __future__ import annotations

import numpy as np
import pytest

from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.evaluation.rollout import run_policy
from solarchain_eval.supply.metrics import bullwhip_ratio, supply_episode_metrics
from solarchain_eval.tasks import DIMENSIONS, Task, get_task, metric_names, metrics_of, task_names
from supply_fixtures import supply_dir, supply_table  # noqa: F401

SEEDS = [20260511, 20260512]


def test_the_supply_task_is_registered_and_declares_its_levers_and_metrics():
    task = get_task("supply-chain")
    assert isinstance(task, Task) and "supply-chain" in task_names() and task.env_id == "SupplyChainEval-v0"
    assert [lever.name for lever in task.levers] == ["supplier_incentive", "release_ratio", "demand_damping"]
    assert all((lever.low, lever.high) == (0.0, 1.0) for lever in task.levers)
    assert {m.dimension for m in task.metrics} == set(DIMENSIONS) - {"auditability"}
    assert [m.name for m in metrics_of(task, "safety")] == [
        "violation_rate",
        "phantom_backed_units",
        "phantom_fill_volume_units",
    ]
    assert sorted(task.baselines()) == ["base-stock", "myopic", "random", "static"]
    assert task.identity(BenchmarkConfig()) == {"env": "SupplyChainEval-v0"}


def _run(task, data, name, config=None):
    config = config or BenchmarkConfig()
    env = task.make_env(config, data)
    policy = task.baselines()[name](config)
    return list(run_policy(env, policy, setting="main", run_seeds=SEEDS, episodes=2, task=task)), env


@pytest.mark.parametrize("name", ["static", "random", "myopic", "base-stock"])
def test_every_baseline_runs_through_the_generic_rollout_deterministically(supply_dir, name):  # noqa: F811
    task = get_task("supply-chain")
    data = task.load_data(task.data_dir(supply_dir, None))
    first, env = _run(task, data, name)
    again, _ = _run(task, data, name)
    assert [r.metrics for r in first] == [r.metrics for r in again]
    assert [(r.run_seed, r.episode) for r in first] == [(s, e) for s in SEEDS for e in (0, 1)]
    last = first[-1]
    assert list(last.steps) == list(task.step_fields) and last.n_steps == 24
    assert list(last.metrics) == list(metric_names(task))
    assert last.metrics == supply_episode_metrics(last.steps, np.asarray(list(env.region_totals.values())))
    assert len(last.city_rewards) == 24 and len(last.city_rewards[0]) == 5  # each region's fill rate
    assert last.metrics["fill_volume_units"] == pytest.approx(float(np.sum(last.steps["filled_units"])))
    assert task.provenance(data)["files"].keys() == {"regions.csv", "demand.csv", "inventory_reports.csv"}


def test_the_reference_policy_trusts_the_reports_and_ships_on_phantom_stock(supply_dir):  # noqa: F811
    task = get_task("supply-chain")
    data = task.load_data(supply_dir)
    base_stock, _ = _run(task, data, "base-stock")
    static, _ = _run(task, data, "static")
    assert sum(r.metrics["phantom_backed_units"] for r in base_stock) > 0.0
    assert all(r.metrics["action_jitter"] == 0.0 and r.metrics["bullwhip_ratio"] == 0.0 for r in static)
    assert all(set(r.steps["release_ratio"]) == {1.0} for r in base_stock)


def test_removing_the_penalty_changes_the_reward_but_not_the_dynamics(supply_dir):  # noqa: F811
    task = get_task("supply-chain")
    data = task.load_data(supply_dir)
    with_penalty, _ = _run(task, data, "base-stock")
    without, _ = _run(task, data, "base-stock", BenchmarkConfig(no_physics_penalty=True))
    assert sum(r.metrics["phantom_backed_units"] for r in with_penalty) > 0.0
    for a, b in zip(with_penalty, without, strict=True):
        for field in task.step_fields:
            if field != "reward":
                assert a.steps[field] == b.steps[field], field
        scale = float(data.demand_mean_units.sum())
        term = 2.0 * (np.asarray(a.steps["violation_rate"]) + np.asarray(a.steps["unsafe_units"]) / scale)
        np.testing.assert_allclose(np.subtract(b.steps["reward"], a.steps["reward"]), term, atol=1e-12)
    assert sum(r.metrics["cumulative_reward"] for r in without) > sum(
        r.metrics["cumulative_reward"] for r in with_penalty
    )


def test_the_bullwhip_ratio_is_the_variance_ratio():
    assert bullwhip_ratio(np.array([0.0, 10.0, 0.0, 10.0]), np.array([4.0, 6.0, 4.0, 6.0])) == pytest.approx(25.0)
    assert bullwhip_ratio(np.ones(4), np.full(4, 3.0)) == 0.0


def test_without_a_directory_the_task_uses_the_default_build_made_once_into_the_cache(isolated_cache):
    import json

    task = get_task("supply-chain")
    path = task.data_dir(None, BenchmarkConfig())
    assert path == isolated_cache / "datasets" / "supply-chain-v0-seed20260511"
    manifest = json.loads((path / "manifest.json").read_text())
    assert manifest["seed"] == 20260511 and manifest["days"] == 364 and manifest["fdia"]["injected_records"] == 91
    assert task.data_dir(None, BenchmarkConfig()) == path and task.load_data(path).days == 364


def test_the_task_gives_its_native_vector_env_which_the_bench_measures(supply_dir, supply_table):  # noqa: F811
    from solarchain_eval.perf.env_bench import vector_env_steps_per_s
    from solarchain_eval.supply.vector import SupplyChainVectorEnv
    from solarchain_eval.tasks.base import make_vector_env

    task = get_task("supply-chain")
    envs = make_vector_env(task, BenchmarkConfig(), supply_table, 3, action_mode="discrete")
    assert isinstance(envs, SupplyChainVectorEnv) and envs.num_envs == 3 and envs.single_action_space.n == 125
    with pytest.raises(ValueError, match="NEXT_STEP only"):
        make_vector_env(task, BenchmarkConfig(), supply_table, 3, autoreset_mode="SameStep")
    result = vector_env_steps_per_s(supply_dir, 4, 25, 1, "supply-chain")
    assert result.name == "vector env, 4 envs (resets included; NEXT_STEP autoreset)" and result.samples[0] > 0
