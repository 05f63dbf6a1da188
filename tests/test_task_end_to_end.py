"""The recipe of docs/architecture.md#add-a-task, walked end to end with the command line: a task
defined only under tests/ (tests/toy_task.py) with one more metric declared in one place, then
``evaluate --task`` -> ``report`` -> ``leaderboard`` -> ``verify`` -> ``paper --task --preset smoke``,
with no edit to a generic wing."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.records_schema import EPISODE_KEYS, Column
from solarchain_eval.tasks import MetricSpec, get_task, register_task, unregister_task
from toy_task import ToyTask

runner = CliRunner()
#: The one declaration a newcomer writes to add a metric (and computes in ``episode_metrics``).
IDLE = MetricSpec(Column("idle_stock_units", "units", "mean stock left on hand after each hour"), "utility", "lower")


class ToyWithIdle(ToyTask):
    metrics = (*ToyTask.metrics, IDLE)

    def episode_metrics(self, steps, env):
        return {**super().episode_metrics(steps, env), "idle_stock_units": float(np.mean(steps["stock"]))}


@pytest.fixture
def toy():
    task = ToyWithIdle()
    register_task(task)  # step 2 of the recipe: make the task known by its name
    yield task
    unregister_task(task.name)


def _ok(args):
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


def test_a_task_from_the_tests_runs_evaluate_report_leaderboard_verify(toy, tmp_path):
    run, report, board = tmp_path / "run", tmp_path / "report", tmp_path / "board"
    _ok(["evaluate", "--task", "toy-stock", "--policies", "steady", "--seeds", "7,8", "--episodes", "3", "--out", run])
    metrics = pd.read_csv(run / "metrics.csv")
    assert list(metrics.columns) == [
        *EPISODE_KEYS,
        "total_reward",
        "shortfall_units",
        "stock_swing",
        "idle_stock_units",
    ]
    actions = pd.read_csv(run / "actions.csv")
    first = actions[(actions.run_seed == 7) & (actions.episode == 0)]
    assert metrics.loc[0, "idle_stock_units"] == pytest.approx(float(first["stock"].mean()), abs=1e-12)
    assert json.loads((run / "run_metadata.json").read_text())["task"] == "toy-stock"

    _ok(["report", run, "--out", report, "--resamples", "200", "--no-figures"])
    utility = (report / "tables" / "task_utility.md").read_text(encoding="utf-8")
    assert "idle_stock_units (units) ↓" in utility  # the declared unit and direction, with no other edit
    mean = metrics["idle_stock_units"].mean()
    assert f"{mean:.3f} ±" in utility or f"{mean:.2f} ±" in utility or f"{mean:.4f} ±" in utility

    _ok(["leaderboard", run, "--out", board, "--resamples", "200"])
    board_csv = pd.read_csv(board / "leaderboard.csv")
    assert board_csv.loc[0, "idle_stock_units_mean"] == pytest.approx(mean, abs=1e-9)
    assert "| idle_stock_units (units) ↓ |" in (board / "leaderboard.md").read_text(encoding="utf-8")

    verified = _ok(["verify", run])
    assert "steady: verified" in verified


def test_a_task_from_the_tests_runs_the_paper_grid_smoke_preset(toy, tmp_path):
    out = tmp_path / "paper"
    output = _ok(["paper", "--task", "toy-stock", "--preset", "smoke", "--out", out, "--workers", "1"])
    # no governance view: the ungoverned settings only, said in one line
    assert "task 'toy-stock' supplies no governance view: settings main, no_physics only" in output
    metadata = json.loads((out / "paper_metadata.json").read_text())
    assert metadata["complete"] and metadata["identity"]["task"] == "toy-stock"
    assert sorted(p.name for p in (out / "combined").iterdir()) == ["main", "no_physics"]
    combined = pd.read_csv(out / "combined" / "main" / "metrics.csv")
    assert list(combined.columns)[-4:] == ["total_reward", "shortfall_units", "stock_swing", "idle_stock_units"]
    # the task's baseline and the three learned policies, trained on the toy market (DQN in its discrete mode)
    assert list(dict.fromkeys(combined["policy"])) == ["steady", "ppo", "sac", "dqn"]
    assert not (out / "combined" / "main" / "city_hour_policy.csv").exists()  # the toy records no extras
    assert "idle_stock_units (units) ↓" in (out / "report" / "tables" / "task_utility.md").read_text(encoding="utf-8")
    # the ablation the grid ran (no_physics - main), per policy and declared metric, paired on the same episodes
    contrast = pd.read_csv(out / "report" / "tables" / "task_contrast_ablation.csv")
    assert set(contrast["comparison"]) == {"no_physics − main"} and contrast["paired"].all()
    both = pd.concat([combined, pd.read_csv(out / "combined" / "no_physics" / "metrics.csv")])
    means = both[both["policy"] == "ppo"].groupby("setting")["idle_stock_units"].mean()
    row = contrast[(contrast["policy"] == "ppo") & (contrast["metric"] == "idle_stock_units")].iloc[0]
    assert row["difference"] == pytest.approx(means["no_physics"] - means["main"], abs=1e-9)
    # the toy market has no calendar (every episode starts at hour 0): one cluster gives no interval, said so
    assert np.isnan(row["low"]) and np.isnan(row["high"]) and not row["excludes_zero"]
    assert "[n/a, n/a]" in (out / "report" / "tables" / "task_contrast_ablation.md").read_text(encoding="utf-8")
    assert (out / "report" / "figures" / "task_contrast_safety.png").exists()
    assert get_task("toy-stock") is toy
