"""``solarchain-eval report``: every paper table and figure regenerated from a run."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table
from rich.text import Text

from ..report.options import (
    AGAINST_CHOICES,
    CLUSTER_UNITS,
    DEFAULT_RESAMPLES,
    DEFAULT_SEED,
    FORMATS,
    ReportDataError,
    ReportOptions,
    parse_formats,
)
from . import app
from .common import (
    CliError,
    cli_error,
    console,
    err_console,
    refuse_file_out,
    register_user_error,
    reports_errors,
    say,
)

register_user_error(ReportDataError)


def _case(text: str) -> tuple[str, str]:
    policy, _, setting = text.partition(":")
    if not policy or not setting:
        raise CliError(f"--case must be POLICY:SETTING (e.g. ppo:llm_no_physics), got '{text}'")
    return policy.strip().lower(), setting.strip()


def _print_check(table) -> None:
    """One against-paper table on the console (its cells as the files print them), or why it is missing."""
    from ..report.paper.tables import ReportTable

    if not isinstance(table, ReportTable):
        say(f"{table.title}: skipped: {table.reason}", err=False)
        return
    shown = Table(title=table.title, title_justify="left")
    for column in table.columns:
        shown.add_column(column.header, overflow="fold")
    for row in table.cells():
        shown.add_row(*row)
    console.print(shown)
    say(table.basis, err=False)


@app.command("report")
@reports_errors
def report(
    root: Path = typer.Argument(
        ...,
        metavar="ROOT",
        help="A run directory (from `evaluate --out`), a paper root (with combined/<setting>/) or a suite root "
        "(from `evaluate --suite --out`).",
    ),
    out: Path | None = typer.Option(None, "--out", help="Output folder (default: ROOT/report)."),
    formats: str = typer.Option(
        ",".join(FORMATS),
        "--formats",
        "--format",  # the older name, still accepted
        help="Comma-separated: md, tex, csv (one file per table each), html (index.html). The same name as "
        "leaderboard's --formats; --format is accepted too.",
    ),
    resamples: int = typer.Option(
        DEFAULT_RESAMPLES, "--resamples", min=100, help="Bootstrap resamples per confidence interval."
    ),
    confidence: float = typer.Option(
        0.95, "--confidence", min=0.5, max=0.999, help="Confidence level of every interval."
    ),
    seed: int = typer.Option(
        DEFAULT_SEED, "--seed", help="Seed of the bootstrap and of plotted-point jitter (same seed, same bytes)."
    ),
    cluster_by: str = typer.Option(
        "start_hour",
        "--cluster-by",
        help="Independent unit the bootstrap resamples: start_hour (start day) or episode_seed.",
    ),
    case: str = typer.Option(
        "ppo:llm_no_physics", "--case", help="POLICY:SETTING searched first for the case-study audit trace."
    ),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="Draw the figures (PNG + SVG)."),
    allow_unverified: bool = typer.Option(
        False,
        "--allow-unverified",
        help="Report files that their run metadata does not vouch for (sha256 mismatch, no metadata, left-overs), with a warning each.",
    ),
    against: str | None = typer.Option(
        None,
        "--against",
        metavar="paper",
        help="Check the run against the paper's published values: each cell beside the run's mean and "
        "interval with a verdict (equal, inside, outside, stand-in, not in run), the paper's findings "
        "(holds, flips) and the training-seed spread; printed and written as tables and a page section.",
    ),
) -> None:
    """Regenerate the paper's tables (Markdown, LaTeX booktabs, CSV) and figures (PNG, SVG) from a
    run, with cluster-bootstrap statistics, and write a self-contained ROOT/report/index.html.

    Tables and figures the run cannot support (e.g. no learned policies, no agentic setting)
    are listed with the reason. A run of a task other than the solar market gets one table per
    template dimension of the metrics its task declares instead of the paper's. A suite root gets
    its own: the normalised score per entry, the aggregates (IQM, mean, median, optimality gap) with
    stratified-bootstrap intervals, the probability of improvement, the performance profile and a
    per-entry heat map (docs/suites.md). Same inputs and options give byte-identical files."""
    refuse_file_out(out)
    try:
        chosen = parse_formats(formats)
    except ValueError as error:
        raise cli_error(error) from None
    if cluster_by not in CLUSTER_UNITS:
        raise CliError(f"--cluster-by must be one of {', '.join(CLUSTER_UNITS)}, got '{cluster_by}'")
    if against is not None and against not in AGAINST_CHOICES:
        raise CliError(f"--against must be one of {', '.join(AGAINST_CHOICES)}, got '{against}'")
    case_policy, case_setting = _case(case)
    options = ReportOptions(
        n_resamples=resamples,
        confidence=confidence,
        seed=seed,
        cluster_by=cluster_by,  # type: ignore[arg-type]
        case_policy=case_policy,
        case_setting=case_setting,
    )
    from ..report.paper.build import build_report
    from ..report.paper.figures import FigureFile
    from ..report.paper.tables import ReportTable

    with err_console.status("building the report..."):
        outcome = build_report(
            root,
            out,
            formats=chosen,
            options=options,
            figures=figures,
            allow_unverified=allow_unverified,
            against=against,
        )
    summary = Table(title=f"report for {root}", title_justify="left")
    summary.add_column("kind")
    summary.add_column("name")
    summary.add_column("status")
    for item in [*outcome.tables, *outcome.figures]:
        kind = "table" if item in outcome.tables else "figure"
        made = isinstance(item, (ReportTable, FigureFile))
        status = Text("written", style="green") if made else Text.assemble(("skipped", "yellow"), f": {item.reason}")
        summary.add_row(kind, item.key, status)
    console.print(summary)
    for table in outcome.against:
        _print_check(table)
    for warning in outcome.warnings:
        err_console.print(Text.assemble(("warning:", "yellow"), f" {warning}"), soft_wrap=True)
    say(f"wrote {len(outcome.files)} files to {outcome.out_dir}", err=False)
    if "html" in chosen:
        say(f"open {outcome.out_dir / 'index.html'}", err=False)
