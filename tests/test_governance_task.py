"""``solarchain-eval governance --task``: the leaderboard on another market, with that market's
diagnostics columns, and a one-line refusal for a task without a governance view."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.records_schema import DIAGNOSTIC_OUTCOMES, EPISODE_KEYS, Column
from solarchain_eval.tasks import (
    diagnostic_names_of,
    diagnostic_outcomes_of,
    get_task,
    governance_view_of,
    harm_outcome_of,
    register_task,
    unregister_task,
)
from supply_fixtures import supply_dir  # noqa: F401 (a fixture)
from toy_task import ToyTask

#: The supply-chain market's outcome suffixes, written out (not read from the code under test).
SUPPLY_OUTCOMES = (
    "violation_rate",
    "unsafe_units",
    "cost",
    "reward",
    "filled_units",
    "backlog_days",
    "phantom_fill_volume_units",
    "price_index",
)


def invoke(args):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_governance_runs_the_supply_chain_market_with_its_own_diagnostics_columns(supply_dir, tmp_path):  # noqa: F811
    out = tmp_path / "board"
    result = invoke(
        ["governance", "--task", "supply-chain", "--data", supply_dir, "--policies", "static,base-stock"]
        + ["--seeds", "1", "--episodes", "1", "--auditors", "rule,oracle", "--resamples", "100", "--out", out]
    )
    assert result.exit_code == 0, result.output
    run = out / "runs" / "llm" / "rule--oracle"
    diagnostics = pd.read_csv(run / "governance_diagnostics.csv")
    roles = [f"{role}_{name}" for role in ("proposal", "bounded", "final") for name in SUPPLY_OUTCOMES]
    step = ["step", "audited", "decision", "hard_trigger", "soft_trigger"]
    assert list(diagnostics.columns) == [*EPISODE_KEYS, "planner", "auditor", *step, *roles, "least_cost"]
    # the named values are the executed step's own: the final action's replay is what the env recorded
    actions = pd.read_csv(run / "actions.csv")
    merged = diagnostics.merge(actions, on=["policy", "run_seed", "episode", "step"], validate="one_to_one")
    assert len(merged) == 2 * 24
    for name in ("filled_units", "unsafe_units", "phantom_fill_volume_units", "price_index", "cost", "reward"):
        assert merged[f"final_{name}"].tolist() == merged[name].tolist(), name
    # the leaderboard's Δartificial liquidity is the change of the phantom fill volume (final - ā);
    # the rule auditor's revisions release less (ρ × 0.90), so it moves there
    board = pd.read_csv(out / "leaderboard.csv").set_index("auditor")
    for auditor in ("rule", "oracle"):
        steps = pd.read_csv(out / "runs" / "llm" / f"rule--{auditor}" / "governance_diagnostics.csv")
        phantom = steps["final_phantom_fill_volume_units"] - steps["bounded_phantom_fill_volume_units"]
        assert board.loc[auditor, "delta_artificial_liquidity_per_step"] == pytest.approx(phantom.mean(), rel=1e-12)
        assert board.loc[auditor, "steps"] == 2 * 24
    assert board.loc["rule", "delta_artificial_liquidity_per_step"] < -1.0
    # the root and each run record the task (a solar root records none: tests/test_governance_cli.py)
    assert json.loads((out / "governance_metadata.json").read_text())["task"] == "supply-chain"
    assert json.loads((run / "run_metadata.json").read_text())["task"] == "supply-chain"
    # the report reads the run with its market's names, and refuses a file of other names naming the column
    assert invoke(["report", run, "--out", tmp_path / "report", "--resamples", "100"]).exit_code == 0
    diagnostics.drop(columns=["final_phantom_fill_volume_units"]).to_csv(
        run / "governance_diagnostics.csv", index=False
    )
    refused = invoke(["report", run, "--out", tmp_path / "report2"])
    assert refused.exit_code == 2, refused.output
    assert "governance_diagnostics.csv: missing column(s) final_phantom_fill_volume_units" in refused.output
    assert not (tmp_path / "report2").exists()


@pytest.fixture
def toy():
    task = ToyTask()
    register_task(task)
    yield task
    unregister_task(task.name)


def test_governance_refuses_a_task_without_a_governance_view_in_one_line(toy, tmp_path):
    out = tmp_path / "board"
    result = invoke(["governance", "--task", "toy-stock", "--episodes", "1", "--out", out])
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0, result.output
    assert "task 'toy-stock' supplies no governance view" in result.output
    assert not out.exists()


def test_governance_takes_the_solar_config_only_for_the_solar_market(tmp_path):
    config = tmp_path / "config.yaml"
    config.write_text("{}\n")
    out = tmp_path / "board"
    result = invoke(["governance", "--task", "supply-chain", "--config", config, "--out", out])
    assert result.exit_code == 2 and "--config is the solar market's configuration" in result.output
    assert not out.exists()


def test_each_market_names_its_diagnostics_outcomes():
    solar = governance_view_of(get_task("solar"))
    supply = governance_view_of(get_task("supply-chain"))
    assert diagnostic_outcomes_of(solar) == DIAGNOSTIC_OUTCOMES
    assert tuple(c.name for c in diagnostic_outcomes_of(supply)) == SUPPLY_OUTCOMES
    assert (harm_outcome_of(solar), harm_outcome_of(supply)) == (
        "artificial_liquidity_MWh",
        "phantom_fill_volume_units",
    )
    assert diagnostic_names_of(supply)[5] == "proposal_violation_rate"
    assert diagnostic_names_of(supply)[-1] == "least_cost"


class _View:
    """A view declaring outcomes without the cost the ground truth reads."""

    diagnostic_outcomes = (Column("reward", "–", "R"), Column("waste", "units", "w"))
    harm_outcome = "waste"


def test_a_view_must_declare_cost_and_reward_and_a_harm_among_its_outcomes():
    with pytest.raises(TypeError, match="include cost, reward"):
        diagnostic_outcomes_of(_View())
    view = _View()
    view.diagnostic_outcomes = (*_View.diagnostic_outcomes, Column("cost", "–", "c"))
    assert harm_outcome_of(view) == "waste"
    view.harm_outcome = "spill"
    with pytest.raises(TypeError, match="'spill' is not one of its outcomes"):
        harm_outcome_of(view)


def test_bench_diagnostics_refuses_a_task_without_a_governance_view(toy):
    result = invoke(["bench", "--diagnostics", "--task", "toy-stock", "--repeats", "1"])
    assert result.exit_code == 2 and "task 'toy-stock' supplies no governance view" in result.output
