"""The metrics a terminal results table shows for a task without the paper's table: its declared
``headline_metrics``, else the first ranked metric of each template dimension."""

from __future__ import annotations

import pytest

from solarchain_eval.cli.common import result_columns
from solarchain_eval.records_schema import Column
from solarchain_eval.tasks import get_task
from solarchain_eval.tasks.base import MetricSpec, headline_metrics_of
from toy_task import ToyTask


class _Unranked(ToyTask):
    # an unranked utility metric first: the default skips it for the ranked one after it
    metrics = (
        MetricSpec(Column("mean_stock", "units", "stock held on average"), "utility", "none"),
        *ToyTask.metrics,
        MetricSpec(Column("late_units", "units", "units shipped late"), "safety", "lower"),
    )


def test_without_a_declaration_the_first_ranked_metric_of_each_dimension():
    assert [m.name for m in headline_metrics_of(ToyTask())] == ["total_reward", "shortfall_units", "stock_swing"]
    assert [m.name for m in headline_metrics_of(_Unranked())] == ["total_reward", "shortfall_units", "stock_swing"]


def test_the_supply_chain_market_declares_its_headline_and_the_table_follows_it():
    supply = get_task("supply-chain")
    names = ["cumulative_reward", "fill_volume_units", "violation_rate", "phantom_backed_units"]
    names += ["bullwhip_ratio", "fill_rate_variance"]
    assert [m.name for m in headline_metrics_of(supply)] == names
    assert [c[0] for c in result_columns("supply-chain")] == names
    # the solar market keeps the paper's table
    assert [c[0] for c in result_columns("solar")] == [
        "cumulative_reward",
        "episode_volume",
        "physics_violation_rate",
        "mean_slippage",
        "artificial_liquidity_MWh",
    ]


def test_a_headline_naming_an_undeclared_metric_is_refused():
    task = ToyTask()
    task.headline_metrics = ("total_reward", "profit")
    with pytest.raises(ValueError, match="toy-stock.*undeclared metric.*profit"):
        headline_metrics_of(task)
