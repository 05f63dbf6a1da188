"""``solarchain-eval bench-llm`` against the scripted server (no model needed)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from fake_openai import FakeOpenAI, default_responder, ok, schema_name, user_context
from solarchain_eval.cli import app
from solarchain_eval.llm import StructuredLLM, resolve_llm_settings
from solarchain_eval.perf.llm_bench import run_llm_bench


@pytest.fixture
def key(monkeypatch):
    monkeypatch.setenv("SOLARCHAIN_LLM_API_KEY", "sk-bench-test")


def test_calls_come_in_episode_order_with_distinct_requests(key):
    with FakeOpenAI() as server:
        settings = resolve_llm_settings(api="chat", model="fake-model", base_url=server.base_url)
        client = StructuredLLM(settings)
        ticks = iter(range(100))
        figures = run_llm_bench(client, 2, audits_per_plan=3, cpu_seconds=lambda: 0.5 * next(ticks))
        client.close()
    kinds = [schema_name(s.path, s.body) for s in server.seen]
    assert kinds == ["PlannerOutput", "AuditorOutput", "AuditorOutput", "AuditorOutput"] * 2
    contexts = [user_context(s.path, s.body) for s in server.seen]
    assert len({repr(c) for c in contexts}) == len(contexts)  # no request repeats another (no cache hits)
    planner_risk = [c["episode_statistics"]["max_violation_rate"] for c in contexts[::4]]
    assert planner_risk == [0.0, 0.3]  # calm, then risky
    auditor_steps = [c["step"] for c in contexts if "step" in c]
    assert auditor_steps == [1, 2, 3, 1, 2, 3]
    planner, auditor = figures["planner"].summary(), figures["auditor"].summary()
    assert (planner["valid"], auditor["valid"]) == (2, 6)
    assert planner["mean_prompt_tokens"] == 120 and auditor["mean_completion_tokens"] == 40  # the fake's usage
    assert planner["median_cpu_s"] == 0.5 and figures["auditor"].cpu_s == [0.5] * 6  # after - before, per call
    # the default responder revises even steps and approves odd ones: risky steps are even
    assert set(figures["auditor"].answers["calm"]) == {"approve"}
    assert set(figures["auditor"].answers["risky"]) == {"revise"}


def test_cli_prints_figures_and_counts_invalid_outputs(key):
    def second_plan_invalid(seen):
        if (
            schema_name(seen.path, seen.body) == "PlannerOutput"
            and user_context(seen.path, seen.body)["episode_statistics"]["max_violation_rate"]
        ):
            return ok(seen.path, {"governance_mode": "x"})
        return default_responder(seen)

    with FakeOpenAI(responder=second_plan_invalid) as server:
        result = CliRunner().invoke(
            app,
            [
                "bench-llm",
                "--calls",
                "2",
                "--audits-per-plan",
                "1",
                "--llm-api",
                "chat",
                "--llm-model",
                "fake-model",
                "--llm-base-url",
                server.base_url,
            ],
            terminal_width=250,
        )
    assert result.exit_code == 0, result.output
    planner_row = next(line for line in result.output.splitlines() if line.startswith("│ planner"))
    auditor_row = next(line for line in result.output.splitlines() if line.startswith("│ auditor"))
    assert "1/2" in planner_row and "llm_guarded" in planner_row
    assert "2/2" in auditor_row and "approve" in auditor_row
    assert "invalid planner output" in result.output and "PlannerOutput" in result.output
