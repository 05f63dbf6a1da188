"""The per-episode record schema is the contract between producers, the report and the fixtures.

Each side takes its column names from :mod:`solarchain_eval.records_schema`; these tests fail
when a producer writes a column the schema lacks (or misses one it has), or when the report
reads a column that is not in the schema (a renamed or removed one included).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pandas as pd
import pytest

import solarchain_eval
from report_fixtures import make_paper_root
from solarchain_eval.envs.env import STEP_INFO_KEYS
from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation
from solarchain_eval.governance import AgenticOptions
from solarchain_eval.records_schema import (
    AGENTIC_COLUMNS,
    AGENTIC_METRIC_NAMES,
    AGENTIC_NUMERIC_NAMES,
    ALL_COLUMNS,
    DIAGNOSTIC_NAMES,
    EPISODE_KEYS,
    LLM_AGENT_METRIC_NAMES,
    METRIC_NAMES,
    REMOVED_COLUMNS,
    RENAMED_COLUMNS,
    SWEEP_RESULT_NAMES,
    upgrade_columns,
)
from solarchain_eval.report.loading import ACTION_KEYS, CITY_HOUR_KEYS, LOG_KEYS, load_report_data
from solarchain_eval.report.paper.tables import agentic as agentic_tables
from solarchain_eval.report.paper.tables.common import AGENTIC_COLUMNS as REPORT_AGENTIC_COLUMNS

PACKAGE = Path(solarchain_eval.__file__).parent
#: Column-like names the report derives itself (figure keys and table-internal columns), not read from records.
REPORT_DERIVED = {
    "audit_step_delta",
    "city_hour_liquidity",
    "city_hour_reward",
    # audit-quality quantities report/governance/audit_quality.py derives from governance_diagnostics.csv
    "delta_artificial_liquidity",
    "delta_reward",
    "false_alarm_rate",
    "revision_delta_reward",
    "paired_no_physics_delta",
    "trust_artificial_liquidity",
    "trust_slippage",
}
#: A string constant that looks like a per-episode or per-step column name.
COLUMN_LIKE = re.compile(
    r"^[a-z][a-z_]*_(rate|count|threshold|budget|delta|index|MWh|reward|volume|slippage|jitter|drawdown|price|liquidity)$"
)


def test_every_column_has_a_unit_and_a_meaning():
    # no duplicates
    assert len(ALL_COLUMNS) == len(EPISODE_KEYS) + len(METRIC_NAMES) + len(AGENTIC_METRIC_NAMES) + len(
        LLM_AGENT_METRIC_NAMES
    )
    for column in ALL_COLUMNS.values():
        assert column.unit and column.meaning, column.name
    assert not set(RENAMED_COLUMNS) & set(ALL_COLUMNS) and not set(REMOVED_COLUMNS) & set(ALL_COLUMNS)
    assert set(RENAMED_COLUMNS.values()) <= set(ALL_COLUMNS)


def test_producer_writes_exactly_the_schema_columns(tiny_dataset, tmp_path):
    """An agentic evaluation's metrics.csv header is the schema: identifiers, metrics, agentic columns."""
    spec = EvaluationSpec(
        policies=["myopic"], run_seeds=[3], episodes=1, data_dir=tiny_dataset, agentic=AgenticOptions()
    )
    run_evaluation(spec, tmp_path / "run")
    header = list(pd.read_csv(tmp_path / "run" / "metrics.csv").columns)
    assert header == [*EPISODE_KEYS, *METRIC_NAMES, *AGENTIC_METRIC_NAMES]


def test_producer_writes_exactly_the_diagnostics_schema(tiny_dataset, tmp_path):
    """governance_diagnostics.csv: episode keys, planner, auditor, then the schema's diagnostic columns."""
    spec = EvaluationSpec(
        policies=["myopic"], run_seeds=[3], episodes=1, data_dir=tiny_dataset, agentic=AgenticOptions()
    )
    run_evaluation(spec, tmp_path / "run")
    header = list(pd.read_csv(tmp_path / "run" / "governance_diagnostics.csv").columns)
    assert header == [*EPISODE_KEYS, "planner", "auditor", *DIAGNOSTIC_NAMES]


def test_fixture_writes_exactly_the_schema_columns(tmp_path):
    root = make_paper_root(tmp_path / "paper")
    agentic = pd.read_csv(root / "combined" / "llm" / "metrics.csv")
    assert list(agentic.columns) == [*EPISODE_KEYS, *METRIC_NAMES, *AGENTIC_METRIC_NAMES]
    diagnostics = pd.read_csv(root / "combined" / "llm" / "governance_diagnostics.csv")
    assert list(diagnostics.columns) == [*EPISODE_KEYS, "planner", "auditor", *DIAGNOSTIC_NAMES]
    assert not diagnostics.drop(columns="decision").isna().any().any()  # decision: empty when not audited


def test_report_reads_only_schema_columns():
    assert set(REPORT_AGENTIC_COLUMNS) <= set(AGENTIC_NUMERIC_NAMES)
    assert {name for name, _ in agentic_tables.TRIGGER_COLUMNS} <= set(AGENTIC_NUMERIC_NAMES)
    known = set(ALL_COLUMNS) | set(LOG_KEYS) | set(STEP_INFO_KEYS) | set(ACTION_KEYS) | set(CITY_HOUR_KEYS)
    known |= set(DIAGNOSTIC_NAMES) | set(SWEEP_RESULT_NAMES)
    unknown = []
    for path in sorted([*(PACKAGE / "report").rglob("*.py"), PACKAGE / "cli" / "agentic.py"]):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.Constant) and isinstance(node.value, str)):
                continue
            name = node.value
            if name in RENAMED_COLUMNS or name in REMOVED_COLUMNS:
                unknown.append(f"{path.name}:{node.lineno} reads {name!r}, renamed or removed in the schema")
            elif COLUMN_LIKE.match(name) and name not in known and name not in REPORT_DERIVED:
                unknown.append(f"{path.name}:{node.lineno} reads {name!r}, which no record schema defines")
    assert not unknown, "\n".join(unknown)


def test_sensitivity_report_reads_schema_columns():
    """The sweep's sensitivity metrics are metrics.csv columns or the columns results.csv adds."""
    from solarchain_eval.report.sensitivity import SENSITIVITY_METRICS

    assert "episode_cost" in SWEEP_RESULT_NAMES
    assert set(SENSITIVITY_METRICS) <= set(METRIC_NAMES) | set(SWEEP_RESULT_NAMES)


def test_report_reads_schema_1_files(tmp_path):
    """Files written before the renames load with the new names (the dropped column is gone)."""
    root = make_paper_root(tmp_path / "paper")
    path = root / "combined" / "llm" / "metrics.csv"
    frame = pd.read_csv(path).rename(columns={"llm_retry_count": "llm_failure_count"})
    frame["jitter_trigger_rate"] = frame["soft_trigger_rate"]
    frame.to_csv(path, index=False)
    data = load_report_data(root, allow_unverified=True)
    assert "llm_retry_count" in data.metrics and "llm_failure_count" not in data.metrics
    assert "jitter_trigger_rate" not in data.metrics


@pytest.mark.parametrize(
    ("columns", "plan"),
    [
        (["llm_failure_count", "audit_rate"], {"llm_failure_count": "llm_retry_count"}),
        (["llm_failure_count", "llm_retry_count"], {}),  # both present: the new one wins, the old is kept as is
        (["jitter_trigger_rate"], {"jitter_trigger_rate": None}),
        ([c.name for c in AGENTIC_COLUMNS], {}),
    ],
)
def test_upgrade_plan(columns, plan):
    assert upgrade_columns(columns) == plan
