"""The report reproduces the paper's baseline rows digit for digit, and byte for byte on reruns.

Evaluates Static, Random and Myopic with the paper protocol (3 seeds × 30 episodes) on the
published data, then checks the generated main-performance table and the appendix main-detail
rows against the paper's text.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation
from solarchain_eval.report import ReportOptions, build_report

# tab:main-performance, the paper's Static/Random/Myopic rows (Markdown rendering of the LaTeX).
PAPER_MAIN_ROWS = (
    "| Static | -23.38 ± 0.80 | 0.514 ± 0.099 | 0.4874 ± 0.0166 | 0.0140 ± 0.0020 | 0.1803 ± 0.0419 |",
    "| Random | -25.46 ± 0.91 | 0.480 ± 0.093 | 0.4771 ± 0.0172 | 0.0148 ± 0.0023 | 0.1137 ± 0.0297 |",
    "| Myopic | -23.08 ± 0.80 | 0.456 ± 0.088 | 0.4779 ± 0.0168 | 0.0144 ± 0.0023 | 0.1009 ± 0.0235 |",
)
PAPER_MAIN_LATEX = (
    r"Static & -23.38 $\pm$ 0.80 & 0.514 $\pm$ 0.099 & 0.4874 $\pm$ 0.0166 & 0.0140 $\pm$ 0.0020 & 0.1803 $\pm$ 0.0419 \\",
    r"Random & -25.46 $\pm$ 0.91 & 0.480 $\pm$ 0.093 & 0.4771 $\pm$ 0.0172 & 0.0148 $\pm$ 0.0023 & 0.1137 $\pm$ 0.0297 \\",
    r"Myopic & -23.08 $\pm$ 0.80 & 0.456 $\pm$ 0.088 & 0.4779 $\pm$ 0.0168 & 0.0144 $\pm$ 0.0023 & 0.1009 $\pm$ 0.0235 \\",
)
# tab:app-main-detail, the baselines' rows (the paper sorts them by name; the report keeps its one order).
PAPER_DETAIL_LATEX = (
    r"Static & 90 & -23.38 & -24.86 & -21.65 & 0.514 & 0.4874 & 0.4527--0.5218 & 0.1803 \\",
    r"Random & 90 & -25.46 & -27.34 & -23.28 & 0.480 & 0.4771 & 0.4395--0.5147 & 0.1137 \\",
    r"Myopic & 90 & -23.08 & -24.60 & -21.39 & 0.456 & 0.4779 & 0.4434--0.5136 & 0.1009 \\",
)
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
    assert tuple(table_rows) == PAPER_MAIN_ROWS
    latex = (report_dir / "tables" / "main_performance.tex").read_text(encoding="utf-8")
    assert [line for line in latex.splitlines() if "$\\pm$" in line and line.endswith("\\\\")] == list(PAPER_MAIN_LATEX)
    assert "\\toprule" in latex and "\\label{tab:main-performance}" in latex
    assert "n = 90 rollouts per row, behind them 32 distinct episode seeds and 21 distinct start days" in markdown


def test_main_detail_equals_the_paper(report_dir: Path):
    latex = (report_dir / "tables" / "main_detail.tex").read_text(encoding="utf-8")
    rows = [line for line in latex.splitlines() if line.endswith("\\\\") and " & 90 & " in line]
    assert rows == list(PAPER_DETAIL_LATEX)


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
