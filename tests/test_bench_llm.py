"""``solarchain-eval bench-llm`` against the scripted server (no model needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from fake_openai import FakeOpenAI, default_responder, ok, schema_name, user_context
from solarchain_eval.cli import app
from solarchain_eval.cli.common import CliError
from solarchain_eval.governance.request import GovernanceRequest
from solarchain_eval.llm import LLMConfigError, StructuredLLM, resolve_llm_settings
from solarchain_eval.llm.serving import local_server
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
    # the situations are the solar market's, reached through the task: its lever ranges, its features
    solar_ranges = {"reward_ratio": [0.05, 0.65], "liquidity_ratio": [0.2, 0.95], "burn_rate": [0.0, 0.2]}
    assert all(c["benchmark_ranges"] == {**solar_ranges, "max_total_allocation": 0.98} for c in contexts)
    assert {"verified_supply_MWh", "raw_physics_record_rate", "static_slippage"} <= set(contexts[1]["observation"])
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


ENDPOINT_VARS = ("SOLARCHAIN_LLM_BASE_URL", "OPENAI_BASE_URL")


@pytest.fixture
def local_model(monkeypatch, tmp_path):
    """Set whether llama-cpp-python and the default model package are installed (nothing runs)."""
    for name in (*ENDPOINT_VARS, "SOLARCHAIN_LLM_MODEL", "OPENAI_MODEL", "SOLARCHAIN_LLM_API_KEY", "OPENAI_API_KEY"):
        monkeypatch.delenv(name, raising=False)
    gguf = tmp_path / "model.gguf"
    gguf.write_bytes(b"GGUF")

    def install(llama: bool, model: bool) -> Path:
        def default_model_path() -> Path:
            if not model:
                raise LLMConfigError("the default local model is not installed")
            return gguf

        monkeypatch.setattr(local_server, "llama_cpp_available", lambda: llama)
        monkeypatch.setattr(local_server, "default_model_path", default_model_path)
        return gguf

    return install


def _backend(environ=None, **given):
    from solarchain_eval.cli.llm import bench_backend

    return bench_backend(GovernanceRequest(**{"llm_backend": None, **given}), environ=environ or {})


def test_bench_llm_measures_the_local_model_when_nothing_names_an_endpoint(local_model):
    local_model(llama=True, model=True)
    assert _backend() == "local"
    assert _backend(llm_api="chat-json-object", llm_threads=1) == "local"
    assert _backend(llm_backend="remote") == "remote"  # an explicit choice stands
    # an endpoint, by flag or environment, or an API only a remote server speaks: remote
    assert _backend(llm_base_url="http://127.0.0.1:9/v1") == "remote"
    for name in ENDPOINT_VARS:
        assert _backend({name: "http://127.0.0.1:9/v1"}) == "remote"
    assert _backend({"OPENAI_BASE_URL": ""}) == "local"  # set but empty: no endpoint
    assert _backend(llm_api="responses") == "remote" and _backend(llm_api="chat") == "remote"
    assert _backend(llm_model="gpt-4o-mini") == "remote"  # a model name, not a GGUF file


def test_bench_llm_serves_a_given_gguf_file_without_the_model_package(local_model):
    gguf = local_model(llama=True, model=False)
    assert _backend(llm_model=str(gguf)) == "local"


@pytest.mark.parametrize(("llama", "model"), [(False, True), (True, False), (False, False)])
def test_bench_llm_without_endpoint_or_local_model_says_how_to_get_one(local_model, llama, model):
    local_model(llama=llama, model=model)
    with pytest.raises(CliError) as caught:
        _backend()
    message = str(caught.value)
    assert "pip install -e '.[llm]'" in message and "--llm-base-url" in message, message
    assert "\n" not in message
    assert _backend(llm_model="gpt-4o-mini") == "remote"  # a remote model by name: the remote checks speak


def test_bench_llm_with_no_options_and_no_model_fails_in_one_line_saying_how(local_model):
    local_model(llama=False, model=False)
    result = CliRunner().invoke(app, ["bench-llm"])
    text = result.output.strip()
    assert result.exit_code == 2, text
    assert len(text.splitlines()) == 1 and text.startswith("error: "), text
    assert "pip install -e '.[llm]'" in text and "--llm-base-url" in text, text
    assert "choose the API explicitly" not in text, text
    help_text = CliRunner().invoke(app, ["bench-llm", "--help"], terminal_width=200)
    assert help_text.exit_code == 0 and "--llm-backend" in help_text.output, help_text.output
