"""Figures, the self-contained index.html (checked in headless Chromium) and the CLI."""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from chromium import find_chromium, open_page
from report_fixtures import make_paper_root
from solarchain_eval.cli import app
from solarchain_eval.report import ReportOptions, build_report
from solarchain_eval.report.paper.figures import POLICY_COLOURS, FigureFile
from solarchain_eval.report.paper.tables import ReportTable

OPTIONS = ReportOptions(n_resamples=200)


@pytest.fixture(scope="module")
def full_report(tmp_path_factory: pytest.TempPathFactory):
    root = make_paper_root(tmp_path_factory.mktemp("paper-root"))
    return build_report(root, options=OPTIONS)


def test_every_figure_is_drawn_as_png_and_svg(full_report):
    figures = full_report.figures
    assert all(isinstance(f, FigureFile) for f in figures), [f for f in figures if not isinstance(f, FigureFile)]
    assert len(figures) == 18  # with the two governance figures
    for figure in figures:
        assert figure.png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert b"<svg" in figure.svg.read_bytes()[:2000]
        assert b"<dc:date>" not in figure.svg.read_bytes()


def test_agentic_figures_name_the_planner_and_auditor_that_ran(full_report):
    by_key = {f.key: f for f in full_report.figures}
    for key in ("jitter_change", "agentic_paired_deltas", "audit_step_delta", "case_action_revision", "case_context"):
        assert by_key[key].title.endswith("(rule planner, rule auditor)"), key
        assert by_key[key].caption.endswith("Planner/Auditor: rule planner, rule auditor."), key
    assert "planner" not in by_key["reward_distribution"].title


def test_policy_colours_are_the_same_in_every_figure(full_report):
    by_key = {f.key: f.svg.read_text(encoding="utf-8").lower() for f in full_report.figures}
    for key in (
        "reward_distribution",
        "utility_safety_frontier",
        "reward_trajectory",
        "trust_slippage",
        "jitter_change",
        "audit_step_delta",
    ):
        assert POLICY_COLOURS["ppo"] in by_key[key], key
        assert POLICY_COLOURS["dqn"] in by_key[key], key
    assert POLICY_COLOURS["static"] in by_key["reward_distribution"]
    assert POLICY_COLOURS["static"] not in by_key["jitter_change"]  # learned policies only


def test_index_html_is_self_contained(full_report):
    page = (full_report.out_dir / "index.html").read_text(encoding="utf-8")
    sources = re.findall(r'\ssrc="([^"]*)"', page)
    assert len(sources) == len(full_report.figures)
    assert all(s.startswith("data:image/png;base64,") for s in sources)
    assert "<script" not in page
    assert not re.search(r'(href|src)="(https?:)?//', page)
    tables = [t for t in full_report.tables if isinstance(t, ReportTable)]
    assert page.count('<figure class="table"') == len(tables) == 14
    for section in ("Dataset provenance", "Run metadata", "Rollouts overlap"):
        assert section in page
    assert "market_liquidity.csv" in page and "missing" in page  # recorded checksum, data dir gone


def test_index_html_renders_in_headless_chromium(full_report, tmp_path):
    if find_chromium() is None:
        pytest.skip("Chromium is not installed (Debian: apt-get install -y chromium)")
    pytest.importorskip("websocket", reason="the websocket-client package (test extra) drives Chromium")
    page, shots = open_page(full_report.out_dir / "index.html", screenshots={"top": (0, 0, 1280, 900)})
    assert page.console_errors == []
    assert page.title.startswith("SolarChain-Eval report")
    assert len(page.images) == len(full_report.figures)
    for image in page.images:
        assert image["complete"] and image["naturalWidth"] > 0 and image["naturalHeight"] > 0, image
    assert all(url.startswith(("file:", "data:")) for url in page.requests), page.requests
    assert shots["top"][:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_report_formats_and_errors(full_report, tmp_path):
    runner = CliRunner()
    root = full_report.data.root
    out = tmp_path / "out"
    result = runner.invoke(
        app, ["report", str(root), "--out", str(out), "--format", "md,csv", "--no-figures", "--resamples", "100"]
    )
    assert result.exit_code == 0, result.output
    assert (out / "tables" / "main_performance.md").is_file() and (out / "tables" / "main_performance.csv").is_file()
    assert not list(out.rglob("*.tex")) and not (out / "index.html").exists() and not (out / "figures").exists()
    assert f"wrote {len(list(out.rglob('*.*')))} files to {out}" in " ".join(result.output.split())
    bad = runner.invoke(app, ["report", str(root), "--format", "md,pdf"])
    assert bad.exit_code == 2 and "unknown report format(s) pdf" in bad.output
    missing = runner.invoke(app, ["report", str(tmp_path / "nowhere")])
    assert missing.exit_code == 2 and "no such directory" in missing.output
    cluster = runner.invoke(app, ["report", str(root), "--cluster-by", "city"])
    assert cluster.exit_code == 2 and "--cluster-by must be one of" in cluster.output
