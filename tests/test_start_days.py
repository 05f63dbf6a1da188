"""Start days, the report's resampling unit, come from the task's steps per day: the solar market's
``start_hour // 24``, the supply-chain market's ``start_hour`` itself (one step = one day).

A supply-chain governance run is reported twice here: by ``solarchain-eval governance`` (its
leaderboard) and by ``solarchain-eval report`` on one of its run directories (the governance
section a non-solar report now has). Both must count and resample one cluster per distinct
``start_hour``, which ``start_hour // 24`` would merge.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.report.governance.audit_quality import audit_quality, ratio_interval
from solarchain_eval.report.sensitivity import sensitivity_table
from solarchain_eval.report.statistics import start_days
from solarchain_eval.tasks import get_task
from solarchain_eval.tasks.base import DEFAULT_STEPS_PER_DAY, steps_per_day_of
from supply_fixtures import supply_dir  # noqa: F401 (a fixture)
from toy_task import ToyTask

RESAMPLES = 300


def invoke(args):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_each_market_declares_its_steps_per_day():
    assert steps_per_day_of(get_task("solar")) == DEFAULT_STEPS_PER_DAY == 24
    assert steps_per_day_of(get_task("supply-chain")) == 1
    assert steps_per_day_of(ToyTask()) == 24  # a task without the attribute: hours, as the solar market
    assert steps_per_day_of(None) == 24  # a run that records no task is a solar run


@pytest.mark.parametrize("bad", [0, -3, 1.5, "1", True])
def test_a_bad_steps_per_day_is_a_one_line_error_naming_the_task(bad):
    task = ToyTask()
    object.__setattr__(task, "steps_per_day", bad)
    with pytest.raises(ValueError, match=r"task 'toy-stock': steps_per_day must be a positive integer"):
        steps_per_day_of(task)


def test_start_days_divide_by_the_steps_per_day():
    hours = [0, 23, 24, 49, 71]
    assert start_days(hours).tolist() == [0, 0, 1, 2, 2]
    assert start_days(hours, 1).tolist() == hours
    assert start_days(pd.Series(hours, dtype=float), 7).tolist() == [0, 3, 3, 7, 10]


@pytest.fixture(scope="module")
def supply_board(supply_dir, tmp_path_factory):  # noqa: F811
    """A supply-chain governance root: two policies, 2 run seeds × 3 episodes, rule planner and auditor."""
    out = tmp_path_factory.mktemp("supply-days") / "board"
    result = invoke(
        ["governance", "--task", "supply-chain", "--data", supply_dir, "--policies", "static,base-stock"]
        + ["--seeds", "1,2", "--episodes", "3", "--auditors", "rule", "--resamples", RESAMPLES, "--out", out]
    )
    assert result.exit_code == 0, result.output
    return out


def _diagnostics(board):
    return pd.read_csv(board / "runs" / "llm" / "rule--rule" / "governance_diagnostics.csv")


def _days_per_policy(diagnostics: pd.DataFrame, steps_per_day: int) -> dict[str, int]:
    days = diagnostics.assign(day=diagnostics["start_hour"] // steps_per_day)
    return days.groupby("policy")["day"].nunique().to_dict()


def test_the_supply_run_starts_on_days_that_hours_would_merge(supply_board):
    # the premise of the tests below: distinct start days that // 24 would count as fewer
    diagnostics = _diagnostics(supply_board)
    assert diagnostics["start_hour"].nunique() >= 3
    assert diagnostics["start_hour"].nunique() > (diagnostics["start_hour"] // 24).nunique()


def test_the_governance_leaderboard_counts_supply_start_days_by_day(supply_board):
    diagnostics = _diagnostics(supply_board)
    board = pd.read_csv(supply_board / "leaderboard.csv")
    assert board["start_days"].tolist() == [diagnostics["start_hour"].nunique()]
    by_policy = pd.read_csv(supply_board / "leaderboard_by_policy.csv").set_index("policy")["start_days"]
    assert by_policy.to_dict() == _days_per_policy(diagnostics, 1)
    assert by_policy.to_dict() != _days_per_policy(diagnostics, 24)


def test_a_supply_report_shows_the_governance_section_clustered_by_day(supply_board, tmp_path):
    run = supply_board / "runs" / "llm" / "rule--rule"
    out = tmp_path / "report"
    result = invoke(["report", run, "--out", out, "--resamples", RESAMPLES])
    assert result.exit_code == 0, result.output
    # the governance section (before: nothing for a task without a paper reference)
    for name in ("tables/governance_diagnostics.csv", "figures/governance_precision_recall.png"):
        assert (out / name).is_file(), name
    markdown = (out / "tables" / "governance_diagnostics.md").read_text()
    assert "Δ phantom_fill_volume_units / step" in markdown  # the supply view's harm outcome heads its column
    assert "Governance diagnostics: audit quality" in (out / "report.md").read_text()
    assert 'id="governance_diagnostics"' in (out / "index.html").read_text()

    diagnostics = _diagnostics(supply_board)
    quality = pd.read_csv(out / "tables" / "governance_diagnostics.csv").set_index("policy")
    assert quality["start_days"].to_dict() == _days_per_policy(diagnostics, 1)
    assert f"up to {max(_days_per_policy(diagnostics, 1).values())} start days per row" in markdown
    # the intervals resample one cluster per distinct start_hour, not per start_hour // 24
    policy = "static"
    steps = diagnostics[diagnostics["policy"] == policy]
    unsafe = ((steps["proposal_cost"] - steps["least_cost"]) > 0.01).to_numpy(float)
    audited = steps["audited"].astype(bool).to_numpy(float)
    by = {
        per_day: ratio_interval(
            audited * unsafe, audited, steps["start_hour"].to_numpy() // per_day, n_resamples=RESAMPLES
        )
        for per_day in (1, 24)
    }
    reported = (quality.loc[policy, "precision_low"], quality.loc[policy, "precision_high"])
    assert reported == pytest.approx((by[1].low, by[1].high), rel=1e-12)
    assert reported != pytest.approx((by[24].low, by[24].high), rel=1e-6)


def test_audit_quality_and_the_sensitivity_table_resample_the_days_they_are_given():
    # 4 episodes starting on steps 0, 1, 2, 3: four days of the supply market, one day of the solar one
    rng = np.random.default_rng(0)
    frame = pd.DataFrame(
        {
            "planner": "rule",
            "auditor": "rule",
            "policy": "static",
            "setting": "llm",
            "run_seed": 1,
            "episode": np.repeat(np.arange(4), 3),
            "start_hour": np.repeat(np.arange(4), 3),
            "step": np.tile(np.arange(3), 4),
            "audited": True,
            "decision": "revise",
            "proposal_cost": 1.0,
            "least_cost": 0.0,
            "bounded_cost": 1.0,
            "final_cost": rng.normal(size=12),
            "bounded_reward": 0.0,
            "final_reward": rng.normal(size=12),
            "final_artificial_liquidity_MWh": 0.0,
            "bounded_artificial_liquidity_MWh": 0.0,
        }
    )
    by_day = audit_quality(frame, n_resamples=RESAMPLES, steps_per_day=1).iloc[0]
    by_hour = audit_quality(frame, n_resamples=RESAMPLES).iloc[0]
    assert (by_day["start_days"], by_hour["start_days"]) == (4, 1)
    assert by_day["delta_cost_per_step_low"] < by_day["delta_cost_per_step_high"]
    assert np.isnan(by_hour["delta_cost_per_step_low"])  # one cluster: no interval
    results = frame.assign(axis=1.0, cumulative_reward=frame["final_reward"])
    table = sensitivity_table(results, ["axis"], resamples=RESAMPLES, steps_per_day=1).iloc[0]
    assert table["start_days"] == 4 and table["ci_low"] < table["ci_high"]
    assert sensitivity_table(results, ["axis"], resamples=RESAMPLES).iloc[0]["start_days"] == 1
