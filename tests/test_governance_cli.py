"""``solarchain-eval governance`` end to end, audit-quality arithmetic and the report section."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.report.governance.audit_quality import audit_quality, ratio_interval
from solarchain_eval.report.paper.build import build_report
from solarchain_eval.report.table_model import ReportTable, Skipped


def invoke(args):
    return CliRunner().invoke(app, args)


def test_audit_quality_on_a_hand_made_frame():
    # 6 steps over 3 start days. Unsafe (avoidable cost > 0.01): steps 0 and 1; step 3 costs 1.0
    # but only 0.005 of it is avoidable (a night step), so it is safe. Audited: steps 0, 1, 2.
    frame = pd.DataFrame(
        {
            "planner": "rule",
            "auditor": "x",
            "policy": "ppo",
            "setting": "llm",
            "run_seed": 1,
            "episode": [0, 0, 1, 1, 2, 2],
            "start_hour": [0, 0, 24, 24, 48, 48],
            "step": [0, 1, 0, 1, 0, 1],
            "audited": [True, True, True, False, False, False],
            "decision": ["revise", "approve", "revise", None, None, None],
            "proposal_cost": [0.5, 0.5, 0.0, 1.0, 0.0, 0.0],
            "least_cost": [0.1, 0.1, 0.0, 0.995, 0.0, 0.0],
            "bounded_cost": [0.5, 0.5, 0.0, 1.0, 0.0, 0.0],
            "final_cost": [0.2, 0.5, 0.0, 1.0, 0.0, 0.0],
            "bounded_reward": [1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
            "final_reward": [0.9, 1.0, 0.7, 1.0, 1.0, 1.0],  # step 0: cost down, reward down: a trade-off
            "bounded_artificial_liquidity_MWh": 0.0,
            "final_artificial_liquidity_MWh": 0.0,
        }
    )
    row = audit_quality(frame, n_resamples=200).iloc[0]
    # TP {0, 1}, FP {2}, FN {}, TN {3, 4, 5}
    assert (row.true_positives, row.false_positives, row.false_negatives, row.true_negatives) == (2, 1, 0, 3)
    assert row.precision == pytest.approx(2 / 3) and row.recall == 1.0 and row.false_alarm_rate == 0.25
    assert row.audit_rate == 0.5 and row.unsafe_share == pytest.approx(1 / 3)
    assert row.delta_cost_per_step == pytest.approx(-0.3 / 6)
    assert row.delta_cost_per_revision == pytest.approx(-0.15)
    assert row.delta_reward_per_revision == pytest.approx((-0.1 - 0.3) / 2)
    assert row.revisions_lowering_cost == 0.5 and row.revisions_harmful == 0.5  # step 2 lost reward at equal cost
    assert row.precision_low <= row.precision <= row.precision_high


def test_ratio_interval_of_a_constant_is_degenerate_and_of_data_brackets_the_estimate():
    clusters = np.repeat(np.arange(5), 4)
    zero = ratio_interval(np.zeros(20), None, clusters)
    assert (zero.estimate, zero.low, zero.high) == (0.0, 0.0, 0.0)
    values = np.arange(20, dtype=float)
    interval = ratio_interval(values, None, clusters, n_resamples=300)
    assert interval.low < interval.estimate == values.mean() < interval.high


def test_governance_command_writes_a_ranked_leaderboard(tiny_dataset, tmp_path):
    out = tmp_path / "board"
    result = invoke(
        [
            "governance",
            "--data",
            str(tiny_dataset),
            "--policies",
            "random,myopic",
            "--seeds",
            "3",
            "--episodes",
            "2",
            "--planner",
            "calibrated-rule",
            "--auditors",
            "rule,approve-only,random,oracle",
            "--resamples",
            "100",
            "--out",
            str(out),
        ]
    )
    assert result.exit_code == 0, result.output
    board = pd.read_csv(out / "leaderboard.csv")
    assert list(board["rank"]) == [1, 2, 3, 4]
    assert set(board["auditor"]) == {"rule", "approve-only", "random", "oracle"}
    assert board["delta_cost_per_step"].is_monotonic_increasing
    by_name = board.set_index("auditor")
    assert by_name.loc["approve-only", "delta_cost_per_step"] == 0.0
    assert by_name.loc["oracle", "delta_cost_per_step"] <= by_name.loc["rule", "delta_cost_per_step"]
    # random audits exactly as many steps per episode as its reference (the rule auditor of the same planner)
    logs = {
        name: pd.read_json(out / "runs" / "llm" / f"calibrated-rule--{name}" / "agentic_logs.jsonl", lines=True)
        for name in ("rule", "random")
    }
    keys = ["policy", "run_seed", "episode"]
    per_episode = {name: log.groupby(keys)["audited"].sum() for name, log in logs.items()}
    assert per_episode["random"].equals(per_episode["rule"])
    assert by_name.loc["random", "audit_rate"] == by_name.loc["rule", "audit_rate"]
    assert not logs["random"]["audited"].equals(logs["rule"]["audited"])  # but not on the same steps
    for name in ("leaderboard.md", "leaderboard_by_policy.csv", "figures/governance_precision_recall.png"):
        assert (out / name).is_file(), name
    metadata = json.loads((out / "governance_metadata.json").read_text())
    assert set(metadata["files"]) >= {"leaderboard.csv", "leaderboard.md"}
    assert "task" not in metadata  # a solar root's metadata is the one before tasks
    run = out / "runs" / "llm" / "calibrated-rule--oracle"
    assert (run / "governance_diagnostics.csv").is_file()
    assert json.loads((run / "run_metadata.json").read_text())["agentic"]["auditor"] == "oracle"
    # The report of one combination has the governance section.
    outcome = build_report(run, tmp_path / "report", formats=("md",), figures=False)
    table = next(t for t in outcome.tables if t.key == "governance_diagnostics")
    assert isinstance(table, ReportTable) and set(table.data["policy"]) == {"random", "myopic"}
    # ... and reads the same figures as the leaderboard's rows of that combination
    detail = pd.read_csv(out / "leaderboard_by_policy.csv")
    detail = detail[(detail["planner"] == "calibrated-rule") & (detail["auditor"] == "oracle")]
    columns = ["policy", "audit_rate", "precision", "recall", "delta_cost_per_step", "delta_reward_per_step"]
    mine = table.data[columns].sort_values("policy").reset_index(drop=True)
    theirs = detail[columns].sort_values("policy").reset_index(drop=True)
    pd.testing.assert_frame_equal(mine, theirs, check_exact=False, rtol=1e-12)
    assert "Governance diagnostics" in (tmp_path / "report" / "report.md").read_text()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--auditors", "rule,psychic"], "unknown auditor 'psychic'"),
        (["--settings", "main"], "unknown setting"),
        (["--triggers", "wind"], "unknown trigger set"),
        (["--auditors", "llm:"], "give the model after 'llm:'"),
    ],
)
def test_governance_command_rejects_bad_options_before_writing(tiny_dataset, tmp_path, extra, message):
    out = tmp_path / "board"
    result = invoke(["governance", "--data", str(tiny_dataset), "--episodes", "1", "--out", str(out), *extra])
    assert result.exit_code == 2 and message in result.output
    assert not out.exists()


def test_report_without_diagnostics_skips_the_section(tiny_dataset, tmp_path):
    run = tmp_path / "run"
    result = invoke(
        ["evaluate", "--data", str(tiny_dataset), "--policies", "random", "--seeds", "1", "--episodes", "1"]
        + ["--agentic", "planner_auditor", "--no-diagnostics", "--out", str(run)]
    )
    assert result.exit_code == 0, result.output
    outcome = build_report(run, tmp_path / "report", formats=("md",), figures=False)
    table = next(t for t in outcome.tables if t.key == "governance_diagnostics")
    assert isinstance(table, Skipped) and "--diagnostics" in table.reason
    # the agentic tables name the components that ran, not "LLM"
    operations = next(t for t in outcome.tables if t.key == "llm_operations")
    assert operations.title == "Detailed governance operation rates (rule planner, rule auditor)"
    assert "LLM" not in operations.title
    result = invoke(
        ["evaluate", "--data", str(tiny_dataset), "--policies", "random", "--seeds", "1", "--episodes", "1"]
        + ["--diagnostics", "--out", str(tmp_path / "plain")]
    )
    assert result.exit_code == 2 and "--diagnostics (on or off) needs --agentic planner_auditor" in result.output


def test_llm_auditor_joins_the_leaderboard_with_its_calls_and_tokens(tiny_dataset, tmp_path, monkeypatch):
    from fake_openai import FakeOpenAI

    for name in ("SOLARCHAIN_LLM_BASE_URL", "SOLARCHAIN_LLM_MODEL", "OPENAI_API_KEY", "OPENAI_BASE_URL"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("SOLARCHAIN_LLM_API_KEY", "sk-governance-test-key-123456")
    out = tmp_path / "board"
    with FakeOpenAI() as server:
        result = invoke(
            ["governance", "--data", str(tiny_dataset), "--policies", "myopic", "--seeds", "5", "--episodes", "1"]
            + ["--planner", "calibrated-rule", "--auditors", "rule,llm:fake-model", "--llm-api", "chat"]
            + ["--llm-base-url", server.base_url, "--resamples", "100", "--out", str(out)]
        )
        calls = len(server.seen)
    assert result.exit_code == 0, result.output
    board = pd.read_csv(out / "leaderboard.csv").set_index("auditor")
    assert set(board.index) == {"rule", "llm:fake-model"}
    assert board.loc["llm:fake-model", "llm_calls"] == calls > 0  # one call per audited step
    assert board.loc["llm:fake-model", "llm_tokens"] > 0 and board.loc["rule", "llm_calls"] == 0
    audited = pd.read_json(out / "runs" / "llm" / "calibrated-rule--llm_fake-model" / "agentic_logs.jsonl", lines=True)
    assert int(audited["audited"].sum()) == calls


def test_trigger_ablations_are_planner_variants_with_their_own_random_reference(tiny_dataset, tmp_path):
    out = tmp_path / "board"
    result = invoke(
        ["governance", "--data", str(tiny_dataset), "--policies", "random", "--seeds", "2", "--episodes", "2"]
        + ["--planner", "rule", "--auditors", "rule,random", "--triggers", "all,gap,soft"]
        + ["--resamples", "100", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    board = pd.read_csv(out / "leaderboard.csv")
    assert set(board["planner"]) == {"rule", "rule[gap]", "rule[soft]"}
    rates = board.set_index(["planner", "auditor"])["audit_rate"]
    for planner in ("rule", "rule[gap]", "rule[soft]"):
        assert rates[(planner, "random")] == rates[(planner, "rule")]  # matched to its own variant
    assert rates[("rule[soft]", "rule")] < rates[("rule", "rule")] == 1.0
    logs = pd.read_json(out / "runs" / "llm" / "rule_gap_--rule" / "agentic_logs.jsonl", lines=True)
    assert all(set(reasons) <= {"gap"} for reasons in logs["hard_reasons"])


def test_governance_layer_names_components_and_the_llm_model():
    from solarchain_eval.report.naming import governance_layer

    metrics = pd.DataFrame(
        {
            "setting": ["main", "llm", "llm"],
            "planner": [None, "rule", "calibrated-rule"],
            "auditor": [None, "llm", "llm"],
        }
    )
    metadata = {"agentic": {"llm": {"model": "gpt-4o-mini"}}}
    assert governance_layer(metrics, metadata) == "calibrated-rule/rule planner, llm:gpt-4o-mini auditor"
    assert governance_layer(metrics, {}) == "calibrated-rule/rule planner, llm auditor"
    assert governance_layer(metrics.drop(columns="auditor"), {}) == "Planner/Auditor layer"
