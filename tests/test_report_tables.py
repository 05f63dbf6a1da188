"""Report tables on a synthetic paper root, checked against values computed independently
(stdlib csv/json/statistics over the raw files, not the report's pandas code)."""

from __future__ import annotations

import csv
import json
import statistics
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from report_fixtures import EPISODES, LEARNED, RUN_SEEDS, STEPS, make_paper_root
from solarchain_eval.report import ReportDataError, ReportOptions, load_report_data
from solarchain_eval.report.paper.tables import ReportTable, Skipped, build_tables, to_csv, to_latex, to_markdown

OPTIONS = ReportOptions(n_resamples=200)


@pytest.fixture(scope="module")
def paper_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_paper_root(tmp_path_factory.mktemp("paper-root"))


@pytest.fixture(scope="module")
def tables(paper_root: Path) -> dict[str, ReportTable | Skipped]:
    return {t.key: t for t in build_tables(load_report_data(paper_root), OPTIONS)}


def _metrics(root: Path, setting: str) -> list[dict]:
    with open(root / "combined" / setting / "metrics.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def _logs(root: Path, setting: str) -> list[dict]:
    path = root / "combined" / setting / "agentic_logs.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()]


def _row(table: ReportTable, **match) -> dict:
    rows = [r for r in table.data.to_dict("records") if all(r[k] == v for k, v in match.items())]
    assert len(rows) == 1, (match, len(rows))
    return rows[0]


def test_every_table_is_built_on_a_full_paper_root(tables):
    assert not [t for t in tables.values() if isinstance(t, Skipped)]
    assert len(tables) == 14  # the paper's eleven, two statistics tables, governance diagnostics


def test_main_performance_is_mean_and_sample_std(paper_root, tables):
    table = tables["main_performance"]
    assert list(table.data["policy"]) == ["Static", "Random", "Myopic", "PPO", "SAC", "DQN"]
    rows = [r for r in _metrics(paper_root, "main") if r["policy"] == "sac"]
    values = [float(r["cumulative_reward"]) for r in rows]
    row = _row(table, policy="SAC")
    assert row["cumulative_reward_mean"] == pytest.approx(statistics.fmean(values), abs=1e-12)
    assert row["cumulative_reward_std"] == pytest.approx(statistics.stdev(values), abs=1e-12)
    cell = f"{statistics.fmean(values):.2f} ± {statistics.stdev(values):.2f}"
    assert f"| SAC | {cell} |" in to_markdown(table)
    latex_cell = cell.replace("±", r"$\pm$")
    assert f"SAC & {latex_cell} &" in to_latex(table)
    # n and the distinct episodes behind it: seeds 11..14 and 12..15 -> 5 seeds, 3 start days
    assert table.basis.startswith(
        "n = 8 rollouts per row, behind them 5 distinct episode seeds and 3 distinct start days"
    )
    assert "rollouts overlap" in table.basis


def test_main_detail_in_the_one_order_with_extremes(paper_root, tables):
    table = tables["main_detail"]
    assert list(table.data["policy"]) == ["Static", "Random", "Myopic", "PPO", "SAC", "DQN"]
    violation = [float(r["physics_violation_rate"]) for r in _metrics(paper_root, "main") if r["policy"] == "myopic"]
    assert f"{min(violation):.4f}–{max(violation):.4f}" in to_markdown(table)
    assert f"{min(violation):.4f}--{max(violation):.4f}" in to_latex(table)


def _paired(root: Path, base: str, treated: str, policy: str, column: str) -> list[float]:
    before = {(r["run_seed"], r["episode"]): float(r[column]) for r in _metrics(root, base) if r["policy"] == policy}
    after = {(r["run_seed"], r["episode"]): float(r[column]) for r in _metrics(root, treated) if r["policy"] == policy}
    return [after[k] - before[k] for k in sorted(before)]


def test_physics_ablation_deltas_pair_rollouts(paper_root, tables):
    table = tables["physics_ablation_deltas"]
    assert [(r["comparison"], r["policy"]) for r in table.data.to_dict("records")] == [
        ("RL", "PPO"),
        ("RL", "SAC"),
        ("RL", "DQN"),
        ("RL+LLM", "PPO"),
        ("RL+LLM", "SAC"),
        ("RL+LLM", "DQN"),
    ]
    deltas = _paired(paper_root, "llm", "llm_no_physics", "dqn", "artificial_liquidity_MWh")
    row = _row(table, comparison="RL+LLM", policy="DQN")
    assert row["n"] == len(RUN_SEEDS) * EPISODES
    assert row["artificial_liquidity_MWh_mean"] == pytest.approx(statistics.fmean(deltas), abs=1e-12)
    assert row["artificial_liquidity_MWh_std"] == pytest.approx(statistics.stdev(deltas), abs=1e-12)


def test_agentic_effects_rates_agree_with_the_logs(paper_root, tables):
    table = tables["agentic_effects"]
    steps = [s for s in _logs(paper_root, "llm") if s["policy"] == "ppo"]
    audited = [s for s in steps if s["audited"]]
    row = _row(table, policy="PPO")
    assert row["audit_rate"] == pytest.approx(len(audited) / len(steps), abs=1e-12)
    assert row["revision_rate"] == pytest.approx(
        sum(s["decision"] == "revise" for s in audited) / len(audited), abs=1e-12
    )
    jitter = _paired(paper_root, "main", "llm", "ppo", "action_jitter")
    assert row["action_jitter_mean"] == pytest.approx(statistics.fmean(jitter), abs=1e-12)
    assert not table.notes  # baselines have no LLM run and are not counted as unmatched


def test_llm_operations_and_triggers(paper_root, tables):
    ops = tables["llm_operations"]
    assert [(r["setting"], r["policy"]) for r in ops.data.to_dict("records")][:3] == [
        ("Main", "PPO"),
        ("Main", "SAC"),
        ("Main", "DQN"),
    ]
    steps = [s for s in _logs(paper_root, "llm_no_physics") if s["policy"] == "sac"]
    row = _row(ops, setting="No-physics", policy="SAC")
    assert row["steps"] == len(steps) == len(RUN_SEEDS) * EPISODES * STEPS
    assert row["mean_action_delta"] == pytest.approx(sum(s["action_delta"] for s in steps) / len(steps), abs=1e-9)
    not_triggered = sum(not (s["hard_trigger"] or s["soft_trigger"]) for s in steps) / len(steps)
    assert row["not_triggered_rate"] == pytest.approx(not_triggered, abs=1e-12)
    assert "The LLM retry count is zero for every row and is therefore not shown." in ops.notes
    triggers = tables["llm_triggers"]
    thresholds = [float(r["plan_gap_threshold"]) for r in _metrics(paper_root, "llm") if r["policy"] == "dqn"]
    assert _row(triggers, setting="Main", policy="DQN")["plan_gap_threshold"] == pytest.approx(
        statistics.fmean(thresholds)
    )


def test_four_setting_tables(paper_root, tables):
    learned = tables["four_setting_learned"]
    assert [r["setting"] for r in learned.data.to_dict("records")][::3] == [
        "RL",
        "RL+LLM",
        "RL no-physics",
        "RL+LLM no-physics",
    ]
    aggregate = tables["four_setting_aggregate"]
    rows = [r for r in _metrics(paper_root, "no_physics") if r["policy"] in LEARNED]
    assert _row(aggregate, setting="RL no-physics")["mean_slippage"] == pytest.approx(
        statistics.fmean(float(r["mean_slippage"]) for r in rows), abs=1e-12
    )
    assert aggregate.notes == ["Every row pools PPO/SAC/DQN."]


def test_agentic_paired_deltas_cover_both_rewards(paper_root, tables):
    table = tables["agentic_paired_deltas"]
    slippage = _paired(paper_root, "no_physics", "llm_no_physics", "sac", "mean_slippage")
    assert _row(table, comparison="No-physics", policy="SAC")["mean_slippage_mean"] == pytest.approx(
        statistics.fmean(slippage), abs=1e-12
    )


def test_action_distributions_percentiles(paper_root, tables):
    frame = pd.read_csv(paper_root / "combined" / "llm" / "actions.csv")
    ell = frame.loc[frame["policy"] == "ppo", "liquidity_ratio"].to_numpy()
    row = _row(tables["action_distributions"], setting="LLM Main", policy="PPO")
    assert row["liquidity_ratio_p05"] == pytest.approx(np.percentile(ell, 5))
    assert row["liquidity_ratio_p95"] == pytest.approx(np.percentile(ell, 95))
    assert f"{ell.mean():.3f} ({np.percentile(ell, 5):.3f}–{np.percentile(ell, 95):.3f})" in to_markdown(
        tables["action_distributions"]
    )


def test_case_study_picks_the_largest_revision(paper_root, tables):
    revised = [s for s in _logs(paper_root, "llm_no_physics") if s["policy"] == "ppo" and s["decision"] == "revise"]
    best = max(revised, key=lambda s: s["action_delta"])
    text = to_markdown(tables["case_study"])
    assert "| policy / setting | PPO / LLM No-physics |" in text
    assert f"Episode {best['episode']}, step {best['step']}, hour {best['hour']} (run seed {best['run_seed']})" in text
    assert f"| Action delta | {best['action_delta']:.3f} |" in text
    assert best["reason"] in text


def test_statistical_tests_pool_rl_vs_non_rl(paper_root, tables):
    from scipy import stats

    table = tables["statistical_tests"]
    rows = _metrics(paper_root, "main")
    rl = [float(r["cumulative_reward"]) for r in rows if r["policy"] in LEARNED]
    other = [float(r["cumulative_reward"]) for r in rows if r["policy"] not in LEARNED]
    row = _row(table, setting="Main", comparison="RL vs non-RL")
    assert row["welch_p"] == pytest.approx(stats.ttest_ind(rl, other, equal_var=False).pvalue, rel=1e-12)
    assert (row["n_a"], row["n_b"]) == (24, 24)
    assert row["difference_low"] <= row["difference"] <= row["difference_high"]
    assert 0.0 <= row["probability_of_improvement_low"] <= row["probability_of_improvement_high"] <= 1.0


def test_tables_are_deterministic(paper_root, tables):
    again = {t.key: t for t in build_tables(load_report_data(paper_root), OPTIONS)}
    for key, table in tables.items():
        for render in (to_markdown, to_latex, to_csv):
            assert render(table) == render(again[key]), key


def test_run_dir_without_learned_or_agentic_data_skips_with_reasons(tmp_path, paper_root):
    run = tmp_path / "run"
    run.mkdir()
    frame = pd.read_csv(paper_root / "combined" / "main" / "metrics.csv")
    frame[~frame["policy"].isin(LEARNED)].to_csv(run / "metrics.csv", index=False)
    built = {t.key: t for t in build_tables(load_report_data(run, allow_unverified=True), OPTIONS)}
    assert isinstance(built["main_performance"], ReportTable)
    assert "no learned policies" in built["four_setting_learned"].reason
    assert "no agentic setting" in built["llm_operations"].reason
    assert "no agentic_logs.jsonl" in built["case_study"].reason
    assert "actions.csv" in built["action_distributions"].reason


def test_loading_errors_name_the_file_and_field(tmp_path, paper_root):
    run = tmp_path / "bad"
    run.mkdir()
    frame = pd.read_csv(paper_root / "combined" / "main" / "metrics.csv")
    frame.drop(columns="mean_slippage").to_csv(run / "metrics.csv", index=False)
    with pytest.raises(ReportDataError, match=r"metrics\.csv: missing column\(s\) mean_slippage"):
        load_report_data(run)
    frame.assign(setting="weird").to_csv(run / "metrics.csv", index=False)
    with pytest.raises(ReportDataError, match=r"row 2 has setting 'weird'"):
        load_report_data(run)
    frame.to_csv(run / "metrics.csv", index=False)
    (run / "agentic_logs.jsonl").write_text('{"policy": "ppo"}\nnot json\n')
    with pytest.raises(ReportDataError, match=r"agentic_logs\.jsonl: line 1 lacks key\(s\) setting"):
        load_report_data(run)
    with pytest.raises(ReportDataError, match="no such directory"):
        load_report_data(tmp_path / "missing")


def test_latex_tables_compile_with_booktabs(tables, tmp_path):
    import shutil
    import subprocess

    if shutil.which("pdflatex") is None:
        pytest.skip("pdflatex is not installed (Debian: texlive-latex-base texlive-latex-recommended)")
    body = "\n\\clearpage\n".join(to_latex(t) for t in tables.values())
    source = tmp_path / "tables.tex"
    source.write_text(
        "\\documentclass{article}\n\\usepackage[T1]{fontenc}\n\\usepackage[utf8]{inputenc}\n\\usepackage{booktabs}\n"
        "\\usepackage[margin=0.5in,landscape]{geometry}\n\\begin{document}\n" + body + "\n\\end{document}\n",
        encoding="utf-8",
    )
    result = subprocess.run(
        ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", source.name],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stdout[-2000:]
    assert (tmp_path / "tables.pdf").stat().st_size > 0
