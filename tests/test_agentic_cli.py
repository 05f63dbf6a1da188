"""End to end: ``evaluate --agentic planner_auditor`` with rule and LLM components, record and
replay against a local server, failures and secrets."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from fake_openai import FakeOpenAI, Reply, chat_body, default_responder, schema_name
from solarchain_eval.cli import app
from solarchain_eval.governance import AGENTIC_METRIC_NAMES

KEY = "sk-e2e-SECRET-9f8e7d6c5b4a"
COMPARED_FILES = ("metrics.csv", "actions.csv", "city_hour_policy.csv", "agentic_logs.jsonl", "summary.json")
LOG_KEYS = [
    "policy",
    "setting",
    "run_seed",
    "episode",
    "episode_seed",
    "step",
    "absolute_hour",
    "hour",
    "raw_violation_rate",
    "supply_gap",
    "static_slippage",
    "kappa",
    "hard_trigger",
    "soft_trigger",
    "hard_reasons",
    "audited",
    "skip_reason",
    "plan",
    "proposed_action",
    "bounded_action",
    "final_action",
    "executed_action",
    "decision",
    "action_delta",
    "reason",
    "audits_used",
    "audit_budget",
    "llm",
]


@pytest.fixture
def clean_env(monkeypatch):
    for name in (
        "SOLARCHAIN_LLM_API_KEY",
        "SOLARCHAIN_LLM_BASE_URL",
        "SOLARCHAIN_LLM_MODEL",
        "OPENAI_API_KEY",
        "OPENAI_BASE_URL",
        "OPENAI_MODEL",
    ):
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def invoke(args):
    return CliRunner().invoke(app, args, catch_exceptions=False)


def base_args(data, out, *extra):
    return [
        "evaluate",
        "--data",
        str(data),
        "--policies",
        "myopic,random",
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


def test_rule_layer_run_writes_logs_and_metrics(tiny_dataset, tmp_path, clean_env):
    out = tmp_path / "run"
    result = invoke(base_args(tiny_dataset, out, "--no-physics-penalty"))
    assert result.exit_code == 0, result.output
    metrics = pd.read_csv(out / "metrics.csv")
    assert set(metrics["setting"]) == {"llm_no_physics"} and list(metrics["policy"]) == ["myopic"] * 2 + ["random"] * 2
    assert list(metrics.columns[-len(AGENTIC_METRIC_NAMES) :]) == list(AGENTIC_METRIC_NAMES)
    assert set(metrics["planner"]) == {"rule"} and set(metrics["auditor"]) == {"rule"}
    rows = [json.loads(line) for line in (out / "agentic_logs.jsonl").read_text().splitlines()]
    assert len(rows) == 4 * 24 and list(rows[0]) == LOG_KEYS
    # Per-episode metrics are the log's own aggregates.
    for (policy, episode), group in pd.DataFrame(rows).groupby(["policy", "episode"]):
        row = metrics[(metrics["policy"] == policy) & (metrics["episode"] == episode)].iloc[0]
        assert row["audit_rate"] == group["audited"].sum() / 24
        assert row["hard_trigger_rate"] == group["hard_trigger"].sum() / 24
        assert row["plan_audit_budget"] == group["audit_budget"].iloc[0]
    actions = pd.read_csv(out / "actions.csv")
    assert list(actions["reward_ratio"]) == [r["executed_action"][0] for r in rows]
    meta = json.loads((out / "run_metadata.json").read_text())
    assert (
        meta["setting"] == "llm_no_physics" and meta["agentic"]["planner"] == "rule" and meta["agentic"]["llm"] is None
    )
    assert "Planner/Auditor" in result.output


@pytest.mark.parametrize("api", ["chat", "responses"])
def test_llm_run_records_then_replays_offline_with_identical_files(tiny_dataset, tmp_path, clean_env, api):
    cache = tmp_path / "cache"
    llm = [
        "--planner",
        "llm",
        "--auditor",
        "llm",
        "--llm-api",
        api,
        "--llm-model",
        "fake-model",
        "--llm-cache",
        str(cache),
    ]
    clean_env.setenv("SOLARCHAIN_LLM_API_KEY", KEY)
    with FakeOpenAI() as server:
        recorded = invoke(
            base_args(
                tiny_dataset, tmp_path / "a", *llm, "--llm-base-url", server.base_url, "--llm-cache-mode", "record"
            )
        )
        calls = len(server.seen)
    assert recorded.exit_code == 0, recorded.output
    assert calls > 4  # 4 planner calls and the audits
    clean_env.delenv("SOLARCHAIN_LLM_API_KEY")  # replay needs neither key nor server
    replayed = invoke(
        base_args(tiny_dataset, tmp_path / "b", *llm, "--llm-base-url", server.base_url, "--llm-cache-mode", "replay")
    )
    assert replayed.exit_code == 0, replayed.output
    for name in COMPARED_FILES:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    rows = [json.loads(line) for line in (tmp_path / "a" / "agentic_logs.jsonl").read_text().splitlines()]
    audited = [r for r in rows if r["audited"]]
    assert audited and all(r["llm"]["kind"] == "auditor" and r["llm"]["cache_key"] for r in audited)
    assert {r["decision"] for r in audited} == {"approve", "revise"}
    assert rows[0]["plan"]["governance_mode"] == "llm_guarded" and rows[0]["plan"]["llm"]["kind"] == "planner"
    # the auditor's revision (0.2, 0.6, 0.1) was executed (decode(encode(final)) may move it by an ulp)
    revised = next(r for r in audited if r["decision"] == "revise")
    assert revised["final_action"] == [pytest.approx(0.2), pytest.approx(0.6), pytest.approx(0.1)]
    assert revised["executed_action"] == [pytest.approx(v, abs=1e-7) for v in revised["final_action"]]
    metrics = pd.read_csv(tmp_path / "a" / "metrics.csv")
    assert set(metrics["governance_mode"]) == {"llm_guarded"} and set(metrics["plan_audit_budget"]) == {5}
    # The key is nowhere: run dirs, cache entries, console output.
    for path in tmp_path.rglob("*"):
        if path.is_file():
            assert KEY not in path.read_text(errors="replace"), path
    assert KEY not in recorded.output + replayed.output


def test_replay_miss_fails_the_run_without_output(tiny_dataset, tmp_path, clean_env):
    out = tmp_path / "run"
    args = base_args(
        tiny_dataset,
        out,
        "--planner",
        "llm",
        "--llm-api",
        "chat",
        "--llm-model",
        "m",
        "--llm-cache",
        str(tmp_path / "empty"),
        "--llm-cache-mode",
        "replay",
    )
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2
    assert (
        "no recorded response" in result.output
        and "policy 'myopic'" in result.output
        and "before step 0" in result.output
    )
    assert not (out / "metrics.csv").exists()


def test_refusal_mid_run_fails_with_policy_episode_and_step(tiny_dataset, tmp_path, clean_env):
    clean_env.setenv("SOLARCHAIN_LLM_API_KEY", KEY)

    def refuse_audits(seen):
        if schema_name(seen.path, seen.body) == "AuditorOutput":
            return Reply(200, chat_body(None, refusal="I won't audit markets."))
        return default_responder(seen)

    out = tmp_path / "run"
    with FakeOpenAI(responder=refuse_audits) as server:
        result = CliRunner().invoke(
            app,
            base_args(
                tiny_dataset,
                out,
                "--auditor",
                "llm",
                "--llm-api",
                "chat",
                "--llm-model",
                "m",
                "--llm-base-url",
                server.base_url,
            ),
        )
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert "the model refused: I won't audit markets." in text
    assert "LLM auditor for policy 'myopic', run seed 5, episode 0, step" in text
    assert not (out / "metrics.csv").exists() and KEY not in result.output


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--planner", "llm"], "--llm-api"),
        (["--planner", "llm", "--llm-api", "chat"], "no model"),
        (["--planner", "llm", "--llm-api", "chat", "--llm-model", "m"], "no API key"),
        (["--planner", "oracle"], "unknown planner"),
        (["--llm-cache-mode", "sometimes", "--planner", "llm", "--llm-api", "chat"], "--llm-cache-mode"),
    ],
)
def test_inconsistent_flags_are_one_line_errors(tiny_dataset, tmp_path, clean_env, extra, message):
    result = CliRunner().invoke(app, base_args(tiny_dataset, tmp_path / "run", *extra))
    assert result.exit_code == 2 and message in result.output, result.output


def test_planner_flag_needs_agentic(tiny_dataset, tmp_path, clean_env):
    args = [
        "evaluate",
        "--data",
        str(tiny_dataset),
        "--policies",
        "static",
        "--episodes",
        "1",
        "--out",
        str(tmp_path),
        "--planner",
        "rule",
    ]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "--agentic planner_auditor" in result.output
