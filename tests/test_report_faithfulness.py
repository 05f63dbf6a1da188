"""The report reproduces the paper's baseline rows digit for digit, and byte for byte on reruns.

Evaluates Static, Random and Myopic with the paper protocol (3 seeds × 30 episodes) on the
published data, then checks the generated main-performance table and the appendix main-detail
rows against the paper's text.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from solarchain_eval.common.atomic_files import read_csv_exact
from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation
from solarchain_eval.report import ReportOptions, build_report
from solarchain_eval.report.against_paper.paper_reference import printed_row
from solarchain_eval.report.against_paper.tables import main_table_against_paper

BASELINE_ROWS = ("Static", "Random", "Myopic")


def latex_rows(label: str) -> list[str]:
    """The paper's baseline rows of a table as its LaTeX prints them (from the stored paper values)."""
    return [" & ".join([name, *printed_row(label, (name,))]) + " \\\\" for name in BASELINE_ROWS]


def markdown_rows(label: str) -> list[str]:
    """The same rows as the report's Markdown renders them ("±", "–")."""
    cells = [[name, *printed_row(label, (name,))] for name in BASELINE_ROWS]
    return ["| " + " | ".join(c.replace(" $\\pm$ ", " ± ").replace("--", "–") for c in row) + " |" for row in cells]


OPTIONS = ReportOptions(n_resamples=300)


@pytest.fixture(scope="module")
def baseline_run(published_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    run_dir = tmp_path_factory.mktemp("paper-baselines") / "run"
    spec = EvaluationSpec(policies=["static", "random", "myopic"], data_dir=published_dir)
    run_evaluation(spec, run_dir, command=["test"])
    return run_dir


@pytest.fixture(scope="module")
def report_dir(baseline_run: Path) -> Path:
    outcome = build_report(baseline_run, options=OPTIONS)
    return outcome.out_dir


def test_main_performance_equals_the_paper(report_dir: Path):
    markdown = (report_dir / "tables" / "main_performance.md").read_text(encoding="utf-8")
    table_rows = [line for line in markdown.splitlines() if line.startswith("| ") and "±" in line]
    assert table_rows == markdown_rows("tab:main-performance")
    latex = (report_dir / "tables" / "main_performance.tex").read_text(encoding="utf-8")
    assert [line for line in latex.splitlines() if "$\\pm$" in line and line.endswith("\\\\")] == latex_rows(
        "tab:main-performance"
    )
    assert "\\toprule" in latex and "\\label{tab:main-performance}" in latex
    assert "n = 90 rollouts per row, behind them 32 distinct episode seeds and 21 distinct start days" in markdown


def test_main_detail_equals_the_paper(report_dir: Path):
    latex = (report_dir / "tables" / "main_detail.tex").read_text(encoding="utf-8")
    rows = [line for line in latex.splitlines() if line.endswith("\\\\") and " & 90 & " in line]
    assert rows == latex_rows("tab:app-main-detail")


def test_the_run_commands_table_equals_the_paper_on_the_published_data(baseline_run: Path):
    comparison = main_table_against_paper(read_csv_exact(baseline_run / "metrics.csv"))
    assert (comparison.equal_cells, comparison.cells) == (15, 15)


def test_the_check_against_the_paper_finds_every_baseline_cell_equal(baseline_run: Path, tmp_path: Path):
    outcome = build_report(baseline_run, tmp_path / "report", options=OPTIONS, figures=False, against="paper")
    main = next(t for t in outcome.against if t.key == "against_paper_main").data
    baselines = main[main["row"].isin(BASELINE_ROWS)]
    assert len(baselines) == 15 and set(baselines["verdict"]) == {"equal"}
    assert set(main.loc[~main["row"].isin(BASELINE_ROWS), "verdict"]) == {"not in run"}


def test_tables_not_supported_by_baselines_are_explained(report_dir: Path):
    text = (report_dir / "report.md").read_text(encoding="utf-8")
    assert "## Not produced for this run" in text
    assert (
        "**Four-setting summaries for learned policies** (`four_setting_learned`): the run has no learned policies"
        in text
    )
    assert (
        "Rollouts overlap: a policy's 90 rollouts come from only 32 distinct episode seeds and 21 distinct start days"
        in text
    )
    csv_text = (report_dir / "tables" / "main_performance.csv").read_text(encoding="utf-8")
    assert csv_text.splitlines()[0].startswith(
        "policy,n,distinct_episode_seeds,distinct_start_days,cumulative_reward_mean"
    )


def test_same_inputs_give_byte_identical_outputs(baseline_run: Path, report_dir: Path, tmp_path: Path):
    again = build_report(baseline_run, tmp_path / "again", options=OPTIONS).out_dir
    first = sorted(p.relative_to(report_dir) for p in report_dir.rglob("*") if p.is_file())
    second = sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    assert first == second
    assert any(p.suffix == ".svg" for p in first) and any(p.suffix == ".png" for p in first)
    for relative in first:
        assert (report_dir / relative).read_bytes() == (again / relative).read_bytes(), relative
