"""A second task (tests/toy_task.py), registered in-process, through ``evaluate``, the command
line and ``verify`` with no edit to a generic wing: the recipe of docs/architecture.md#add-a-task."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from solarchain_eval.agents.specs import AgentSpecError
from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.evaluation.verify import VERIFIED, VerifyOptions, verify_run
from solarchain_eval.records_schema import EPISODE_KEYS
from solarchain_eval.tasks import register_task, unregister_task
from toy_task import TOY_TASK

SEEDS = [20260511, 20260512]
TOY_METRICS = ["total_reward", "shortfall_units", "stock_swing"]
runner = CliRunner()


@pytest.fixture
def toy():
    register_task(TOY_TASK)  # step 3 of the recipe: make the task known by its name
    yield TOY_TASK
    unregister_task(TOY_TASK.name)


def _reseal(run: Path, name: str) -> None:
    """Record ``name``'s new sha256, as someone rewriting a run's files and checksums would."""
    path = run / "run_metadata.json"
    meta = json.loads(path.read_text())
    meta["files"][name] = sha256_file(run / name)
    path.write_text(json.dumps(meta, indent=2))


def test_a_task_defined_in_the_tests_runs_through_evaluate_and_verifies(toy, tmp_path):
    run = tmp_path / "run"
    result = solarchain_eval.evaluate("steady", task="toy-stock", seeds=SEEDS, episodes=3, out=run)

    metrics = pd.read_csv(run / "metrics.csv")
    assert list(metrics.columns) == [*EPISODE_KEYS, *TOY_METRICS]  # the task's declared columns, in order
    assert list(result.metrics.columns) == list(metrics.columns) and len(metrics) == 6
    actions = pd.read_csv(run / "actions.csv")
    assert list(actions.columns) == [
        "policy",
        "setting",
        "run_seed",
        "episode",
        "episode_seed",
        "step",
        *toy.step_fields,
    ]
    # each metrics row is the task's episode_metrics of the steps actions.csv records
    first = actions[(actions.run_seed == SEEDS[0]) & (actions.episode == 0)]
    assert len(first) == 12 and metrics.total_reward[0] == pytest.approx(first.reward.sum(), abs=1e-9)
    assert metrics.shortfall_units[0] == pytest.approx(first.shortfall.sum(), abs=1e-9)
    assert sorted(p.name for p in run.iterdir()) == ["actions.csv", "metrics.csv", "run_metadata.json", "summary.json"]

    meta = json.loads((run / "run_metadata.json").read_text())
    assert meta["task"] == "toy-stock" and meta["dataset"] == {"data_dir": None, "files": {}} and meta["config"] == {}
    assert meta["protocol"]["task"] == "toy-stock" and meta["protocol"]["env"] == "ToyStock-v0"
    assert meta["policy_specs"] == ["steady"] and result.protocol_id == meta["protocol_id"]

    check = verify_run(run, VerifyOptions(episodes=6))
    assert check.ok, check.lines()
    (steady,) = check.policies
    assert (steady.policy, steady.status, steady.episodes) == ("steady", VERIFIED, 6)


def test_verify_finds_a_tampered_metric_of_a_task(toy, tmp_path):
    run = tmp_path / "run"
    solarchain_eval.evaluate("steady", task="toy-stock", seeds=SEEDS[:1], episodes=2, out=run)
    metrics = pd.read_csv(run / "metrics.csv")
    metrics.loc[1, "stock_swing"] += 0.5
    metrics.to_csv(run / "metrics.csv", index=False)

    plain = verify_run(run, VerifyOptions(episodes=2))
    assert not plain.ok and any("metrics.csv" in p for p in plain.checksum_problems)

    _reseal(run, "metrics.csv")  # checksums that agree: only the re-run tells
    check = verify_run(run, VerifyOptions(episodes=2))
    (steady,) = check.policies
    assert not check.ok and not check.checksum_problems
    assert steady.difference is not None and (steady.difference.episode, steady.difference.metric) == (1, "stock_swing")

    # a declared column gone: the record schema of the task is not the file's
    metrics.drop(columns=["shortfall_units"]).to_csv(run / "metrics.csv", index=False)
    _reseal(run, "metrics.csv")
    check = verify_run(run, VerifyOptions(episodes=2))
    assert check.rollout_problems == ("metrics.csv lacks column 'shortfall_units' of task 'toy-stock'",)

    metrics.rename(columns={"shortfall_units": "shortfall_MWh"}).to_csv(run / "metrics.csv", index=False)
    _reseal(run, "metrics.csv")
    check = verify_run(run, VerifyOptions(episodes=2))
    assert check.rollout_problems == (
        "metrics.csv lacks column 'shortfall_units' of task 'toy-stock'",
        "metrics.csv has column 'shortfall_MWh', which task 'toy-stock' does not declare",
    )


def test_the_command_line_evaluates_and_verifies_a_task(toy, tmp_path):
    run = tmp_path / "cli-run"
    result = runner.invoke(
        app, ["evaluate", "--task", "toy-stock", "--seeds", "7", "--episodes", "2", "--out", str(run)]
    )
    assert result.exit_code == 0, result.output
    assert "total_reward" in result.output  # the results table shows the task's own metrics
    assert list(pd.read_csv(run / "metrics.csv").columns) == [*EPISODE_KEYS, *TOY_METRICS]
    assert pd.read_csv(run / "metrics.csv").policy.unique().tolist() == ["steady"]  # the task's baselines by default

    checked = runner.invoke(app, ["verify", str(run), "--episodes", "2"])
    assert checked.exit_code == 0, checked.output
    assert "steady: verified (2 episodes" in checked.output

    baselines = runner.invoke(
        app, ["run", "--task", "toy-stock", "--seeds", "7", "--episodes", "1", "--out", str(tmp_path / "b")]
    )
    assert baselines.exit_code == 0, baselines.output
    assert json.loads((tmp_path / "b" / "run_metadata.json").read_text())["policies"] == ["steady"]


def test_a_run_of_a_task_not_installed_fails_verify_in_one_line(toy, tmp_path):
    run = tmp_path / "run"
    solarchain_eval.evaluate("steady", task="toy-stock", seeds=SEEDS[:1], episodes=1, out=run)
    unregister_task("toy-stock")  # the run names a task this process does not have
    result = runner.invoke(app, ["verify", str(run)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "field task: unknown task 'toy-stock' (available: solar" in lines[0]

    unknown = runner.invoke(app, ["evaluate", "--task", "nope", "--out", str(tmp_path / "x")])
    assert unknown.exit_code == 2 and "unknown task 'nope'" in unknown.output
    assert not (tmp_path / "x").exists()


def test_a_task_refuses_the_solar_markets_baselines(toy, tmp_path):
    # the toy market's built-in names are its own baselines (and the learned policies), not the solar market's
    with pytest.raises(AgentSpecError, match="unknown policy 'static': choose from steady, ppo"):
        solarchain_eval.evaluate("static", task="toy-stock", seeds=SEEDS[:1], episodes=1)


def test_a_solar_run_records_no_task(tiny_dataset, tmp_path):
    """The solar market's run files are those before tasks: no ``task`` key, the same protocol fields."""
    run = tmp_path / "run"
    solarchain_eval.evaluate("static", data=tiny_dataset, seeds=SEEDS[:1], episodes=1, out=run)
    meta = json.loads((run / "run_metadata.json").read_text())
    assert "task" not in meta and "task" not in meta["protocol"]
    assert list(meta["protocol"])[:2] == ["env", "records_schema_version"]
    assert (run / "city_hour_policy.csv").is_file()
