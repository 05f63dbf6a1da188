"""The LLM operations table reports every model call's latency and tokens from the logs."""

from __future__ import annotations

import json
import statistics

import pytest
from typer.testing import CliRunner

from fake_openai import FakeOpenAI, Reply, chat_body, default_responder, schema_name
from solarchain_eval.cli import app
from solarchain_eval.report import ReportOptions
from solarchain_eval.report.loading import load_report_data
from solarchain_eval.report.paper.tables.agentic import llm_operations


def _args(data, out, *extra):
    return [
        "evaluate",
        "--data",
        str(data),
        "--policies",
        "myopic",
        "--seeds",
        "5",
        "--episodes",
        "2",
        "--out",
        str(out),
        "--agentic",
        "planner_auditor",
        *extra,
    ]


def _auditor_usage(seen) -> Reply:
    """Default answers; auditor replies report other token counts than the planner's (120/40)."""
    reply = default_responder(seen)
    if schema_name(seen.path, seen.body) == "AuditorOutput":
        content = reply.body["choices"][0]["message"]["content"]
        body = chat_body(content)
        body["usage"] = {"prompt_tokens": 300, "completion_tokens": 70, "total_tokens": 370}
        return Reply(200, body)
    return reply


def test_llm_operations_table_counts_calls_latency_and_tokens(tiny_dataset, tmp_path, monkeypatch):
    monkeypatch.setenv("SOLARCHAIN_LLM_API_KEY", "sk-report-test")
    out = tmp_path / "run"
    with FakeOpenAI(responder=_auditor_usage) as server:
        result = CliRunner().invoke(
            app,
            _args(
                tiny_dataset,
                out,
                "--planner",
                "llm",
                "--auditor",
                "llm",
                "--llm-api",
                "chat",
                "--llm-model",
                "fake-model",
                "--llm-base-url",
                server.base_url,
            ),
            catch_exceptions=False,
        )
        calls = len(server.seen)
    assert result.exit_code == 0, result.output
    rows = [json.loads(line) for line in (out / "agentic_logs.jsonl").read_text().splitlines()]
    audits = [r["llm"]["latency_s"] for r in rows if r["llm"] is not None]
    plans = [r["plan"]["llm"]["latency_s"] for r in rows if r["step"] == 0]
    assert len(plans) == 2 and audits and len(plans) + len(audits) == calls

    table = llm_operations(load_report_data(out), ReportOptions())
    (row,) = table.data.to_dict("records")
    assert row["llm_calls"] == calls
    assert row["planner_median_s"] == pytest.approx(statistics.median(plans))
    assert row["auditor_median_s"] == pytest.approx(statistics.median(audits))
    # the planner's call counts once per episode, not once per logged step
    assert row["mean_prompt_tokens"] == pytest.approx((120 * len(plans) + 300 * len(audits)) / calls)
    assert row["mean_completion_tokens"] == pytest.approx((40 * len(plans) + 70 * len(audits)) / calls)
    headers = [c.header for c in table.columns]
    assert headers[-5:] == ["LLM Calls", "Planner Median s", "Auditor Median s", "Prompt Tokens", "Completion Tokens"]


def test_rule_layer_has_no_llm_call_columns(tiny_dataset, tmp_path):
    out = tmp_path / "run"
    result = CliRunner().invoke(app, _args(tiny_dataset, out), catch_exceptions=False)
    assert result.exit_code == 0, result.output
    table = llm_operations(load_report_data(out), ReportOptions())
    assert "LLM Calls" not in [c.header for c in table.columns]
    assert table.data.to_dict("records")[0]["llm_calls"] == 0
