"""Build the whole report: load, tables, figures, files (Markdown, LaTeX, CSV) and index.html."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ...common.atomic_files import atomic_write_text
from ...experiments.layout import REPORT_DIR
from ...tasks.base import paper_reference_of
from ...tasks.registry import DEFAULT_TASK
from ..against_paper.tables import AGAINST_CHOICES, AGAINST_KEYS, against_paper_tables
from ..governance.figures import governance_figures
from ..governance.tables import governance_diagnostics, has_governance_section
from ..loading import load_report_data
from ..options import FORMATS as FORMATS
from ..options import ReportDataError, ReportOptions
from ..options import parse_formats as parse_formats
from ..outputs import INDEX_FILE as INDEX_FILE
from ..outputs import MARKDOWN_FILE as MARKDOWN_FILE
from ..outputs import TABLE_FORMATS as TABLE_FORMATS
from ..outputs import ReportOutcome as ReportOutcome
from ..outputs import write_tables as write_tables
from ..suite_loading import is_suite_root
from ..suite_report import build_suite_report
from ..task_contrast import contrast_frame, task_contrast_figure, task_contrast_tables
from ..task_summary import NO_PAPER, task_summary_tables
from .figures import FigureFile, build_figures
from .html import render_html
from .tables import ReportTable, Skipped, build_tables, overlap_warning, to_markdown


def _remove_stale(
    out_dir: Path, tables: Sequence[ReportTable | Skipped], figures: Sequence[FigureFile | Skipped]
) -> None:
    """Delete earlier outputs of tables/figures this run skips, so nothing stale is left beside new files."""
    for item in tables:
        if isinstance(item, Skipped):
            for ext in TABLE_FORMATS:
                (out_dir / "tables" / f"{item.key}.{ext}").unlink(missing_ok=True)
    for item in figures:
        if isinstance(item, Skipped):
            for ext in ("png", "svg"):
                (out_dir / "figures" / f"{item.key}.{ext}").unlink(missing_ok=True)


def _against_section(outcome: ReportOutcome) -> list[str]:
    if not outcome.against:
        return []
    lines = ["## Checking the run against the paper", ""]
    for table in outcome.against:
        lines.append(to_markdown(table) if isinstance(table, ReportTable) else f"- **{table.title}**: {table.reason}\n")
    return lines


def _markdown_report(outcome: ReportOutcome) -> str:
    lines = [f"# SolarChain-Eval report: {outcome.data.root}", ""]
    if outcome.data.task != DEFAULT_TASK:
        lines += [f"Task: `{outcome.data.task}`.", ""]
    lines += [f"> **Warning.** {w}\n" for w in outcome.warnings]
    lines += ["## Tables", ""]
    for table in outcome.tables:
        if isinstance(table, ReportTable):
            lines.append(to_markdown(table))
    skipped = [t for t in outcome.tables if isinstance(t, Skipped)] + [
        f for f in outcome.figures if isinstance(f, Skipped)
    ]
    if skipped:
        lines += (
            ["## Not produced for this run", ""] + [f"- **{s.title}** (`{s.key}`): {s.reason}" for s in skipped] + [""]
        )
    lines += _against_section(outcome)
    figures = [f for f in outcome.figures if isinstance(f, FigureFile)]
    if figures:
        lines += ["## Figures", ""] + [f"![{f.title}](figures/{f.key}.png)\n\n*{f.caption}*\n" for f in figures]
    return "\n".join(lines)


def build_report(
    root: Path,
    out_dir: Path | None = None,
    *,
    formats: Sequence[str] = FORMATS,
    options: ReportOptions = ReportOptions(),
    figures: bool = True,
    allow_unverified: bool = False,
    against: str | None = None,
) -> ReportOutcome:
    """Regenerate every table and figure the run at ``root`` supports.

    Parameters
    ----------
    root
        A run directory (``solarchain-eval evaluate --out``), a paper root, or a suite root
        (``evaluate --suite``: its own tables and figures, :mod:`~solarchain_eval.report.suite_report`).
    out_dir
        Output folder (default ``root/report``).
    formats
        Any of "md", "tex", "csv" (one file per table each) and "html" (``index.html``).
    options
        Resampling and selection options.
    figures
        Draw the figures (PNG + SVG); the HTML embeds them.
    allow_unverified
        Report files whose sha256 disagree with their metadata (or lack it), with a warning each.
    against
        ``"paper"``: also check the run against the paper's published values
        (:mod:`~solarchain_eval.report.against_paper.tables`; tables ``against_paper_*``, ``seed_spread``,
        ``seed_rankings`` and a section of the page).

    Raises
    ------
    ReportDataError
        The run's files are missing or malformed.
    ValueError
        ``against`` is not one of :data:`~solarchain_eval.report.against_paper.tables.AGAINST_CHOICES`.
    """
    if against is not None and against not in AGAINST_CHOICES:
        raise ValueError(f"against must be one of {', '.join(AGAINST_CHOICES)}, got {against!r}")
    if is_suite_root(root):
        if against is not None:
            raise ReportDataError(f"{root}: a suite root is checked against no paper (report an entry's run instead)")
        return build_suite_report(
            Path(root), out_dir, formats=formats, options=options, figures=figures, allow_unverified=allow_unverified
        )
    data = load_report_data(Path(root), allow_unverified=allow_unverified)
    out = Path(out_dir) if out_dir is not None else Path(root) / REPORT_DIR
    paper = paper_reference_of(data.task_spec) is not None
    if against == "paper" and not paper:
        raise ReportDataError(f"{root}: task {data.task!r} has no paper reference to check the run against")
    if paper:  # the paper's tables and figures, then the declared metrics they do not cover (if any)
        tables = build_tables(data, options) + task_summary_tables(data, options)
        drawn = build_figures(data, options, out / "figures") if figures else []
    else:  # the paper's tables read the solar market's columns: one line says so, the task's own tables instead
        tables = [Skipped("paper", "The paper's tables and figures", NO_PAPER.format(task=data.task))]
        tables += task_summary_tables(data, options)
        contrasts = contrast_frame(data, options)  # the declared setting contrasts, shared by tables and figure
        tables += task_contrast_tables(data, options, contrasts)
        drawn = [task_contrast_figure(data, options, out / "figures", contrasts)] if figures else []
        if has_governance_section(data):  # the Planner/Auditor layer's diagnostics are every market's
            tables.append(governance_diagnostics(data, options))
            drawn += governance_figures(data, options, out / "figures") if figures else []
    warning = overlap_warning(data.metrics, options.cluster_by)
    outcome = ReportOutcome(out_dir=out, data=data, tables=tables, figures=drawn, warnings=[warning] if warning else [])
    outcome.warnings[:0] = [f"UNVERIFIED INPUT: {problem}" for problem in data.unverified]
    outcome.files += [p for f in drawn if isinstance(f, FigureFile) for p in (f.png, f.svg)]
    outcome.files += write_tables(out, tables, formats)
    if against == "paper":
        outcome.against = against_paper_tables(data, options)
        outcome.files += write_tables(out, outcome.against, formats)
    # a table not made this time (skipped, or the against-paper check not asked for) leaves no old file behind
    made = {t.key for t in outcome.against if isinstance(t, ReportTable)}
    _remove_stale(out, [*tables, *(Skipped(k, k, "") for k in AGAINST_KEYS if k not in made)], drawn)
    if "md" in formats:
        outcome.files.append(atomic_write_text(out / MARKDOWN_FILE, _markdown_report(outcome)))
    if "html" in formats:
        outcome.files.append(
            atomic_write_text(out / INDEX_FILE, render_html(data, tables, drawn, outcome.warnings, outcome.against))
        )
    return outcome
