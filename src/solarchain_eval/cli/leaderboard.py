"""``solarchain-eval leaderboard``: rank runs and paper roots of one task and protocol, per setting, and
suite roots by their suite aggregate, one board per suite protocol."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from ..report.options import (
    DEFAULT_MAX_MEMBERS,
    DEFAULT_MAX_UNPACKED_MB,
    DEFAULT_RESAMPLES,
    LEADERBOARD_FORMATS,
    LeaderboardOptions,
    ReportDataError,
    parse_formats,
)
from . import app
from .common import CliError, cli_error, console, refuse_file_out, register_user_error, reports_errors, say

register_user_error(ReportDataError)


@app.command("leaderboard")
@reports_errors
def leaderboard(
    inputs: list[Path] = typer.Argument(
        ...,
        metavar="RUN_OR_ROOT",
        help="Run directories (evaluate --out), paper roots, tarballs (.tar, .tar.gz, .tgz) of either, or suite "
        "roots (evaluate --suite --out).",
    ),
    out: Path = typer.Option(..., "--out", help="The board's folder (leaderboard.csv, .md, .html, pareto.png)."),
    split: bool = typer.Option(
        False,
        "--split",
        help="Write one board per task and protocol (per suite protocol for suite roots) into OUT/<protocol id>/ "
        "instead of refusing a mix.",
    ),
    formats: str = typer.Option(
        ",".join(LEADERBOARD_FORMATS), "--formats", help="Comma-separated: csv, md, html (md and html add pareto.png)."
    ),
    resamples: int = typer.Option(
        DEFAULT_RESAMPLES, "--resamples", min=100, help="Start-day bootstrap resamples per interval."
    ),
    max_unpacked_mb: float = typer.Option(
        DEFAULT_MAX_UNPACKED_MB,
        "--max-unpacked-mb",
        help="Refuse a tarball whose files unpack to more than this many MB (checked before unpacking).",
    ),
    max_members: int = typer.Option(
        DEFAULT_MAX_MEMBERS,
        "--max-members",
        min=1,
        help="Refuse a tarball of more members (files and folders) than this (checked before unpacking).",
    ),
) -> None:
    """Rank runs and paper roots of one protocol per setting, with start-day bootstrap intervals.

    Per policy and setting: mean cumulative reward and IQM with 95 % intervals, the probability
    of improvement over the best baseline on paired episodes, the safety metrics, the access label
    (isolated, in-process or privileged) and the source. A task other than the solar market is
    ranked by its first utility metric whose direction is higher, with every other metric it
    declares beside it. All inputs must be of one task and share one protocol apart from the
    setting (dataset, run seeds, episodes, episode-seed rule, task configuration); otherwise the
    command names the first differing field and two inputs, and writes nothing. A tarball is
    refused before anything is unpacked when it passes --max-unpacked-mb or --max-members, holds
    a link, or holds a file its metadata does not vouch for; --out may not lie inside an input.

    A suite root (evaluate --suite) is ranked by the IQM of its normalised scores with its
    stratified-bootstrap interval, mean, median and optimality gap beside, on a board of its suite
    protocol id: never beside runs, paper roots or suite roots of another split or protocol
    (refused, or with --split one board each and a line naming the inputs kept apart).
    See docs/comparing_results.md, docs/suites.md and docs/security.md.
    """
    refuse_file_out(out)
    try:
        if not max_unpacked_mb > 0:
            raise ValueError(f"--max-unpacked-mb must be positive, got {max_unpacked_mb:g}")
        options = LeaderboardOptions(
            formats=parse_formats(formats, LEADERBOARD_FORMATS, "leaderboard"),
            split=split,
            n_resamples=resamples,
            max_unpacked_mb=max_unpacked_mb,
            max_members=max_members,
        )
    except ValueError as error:
        raise cli_error(error) from None
    from ..report.leaderboard import make_leaderboards
    from ..report.leaderboard.inputs import LeaderboardError

    try:
        outcome = make_leaderboards(inputs, out, options)
    except LeaderboardError as error:
        raise cli_error(error) from None
    for board in outcome.boards:
        if board.suite is not None:
            console.print(_suite_table(board))
            continue
        ranked = board.layout.ranked.name
        label = board.layout.label(board.layout.ranked) or ranked
        for section in board.sections:
            shown = Table(
                title=f"{section.setting} (board {board.board_id}, protocol {section.protocol_id})",
                title_justify="left",
            )
            for column in ("rank", "policy", "access", f"mean {label} [95 % CI]", "P(> best baseline)", "source"):
                shown.add_column(column, justify="right" if column in ("rank",) else "left")
            for row in section.ranked.to_dict("records"):
                p = row["p_improvement"]
                shown.add_row(
                    str(row["rank"]),
                    str(row["policy"]),
                    str(row["access"]),
                    f"{row[f'{ranked}_mean']:.2f} [{row[f'{ranked}_low']:.2f}, {row[f'{ranked}_high']:.2f}]",
                    "n/a" if p != p else f"{p:.2f}",
                    str(row["source"]),
                )
            console.print(shown)
    for note in outcome.notes:
        say(note, err=False)
    if not outcome.files:
        raise CliError("nothing to write")
    say(f"wrote {len(outcome.files)} files to {outcome.out_dir}", err=False)


def _suite_table(board) -> Table:
    """A suite board on the console: rank, policy, the aggregates with their intervals, source."""
    section = board.sections[0]
    shown = Table(
        title=f"suite {board.suite.suite}, split {', '.join(board.suite.splits)} (suite protocol {board.board_id}): "
        "normalised score, 95 % stratified-bootstrap intervals",
        title_justify="left",
    )
    names = ("iqm", "mean", "optimality_gap")  # the median is in the board's files
    for column in ("rank", "policy", "access", *names, "source"):
        shown.add_column(column.replace("_", " "), justify="right" if column == "rank" else "left")
    for row in section.ranked.to_dict("records"):
        cells = (f"{row[n]:.3f} [{row[f'{n}_low']:.3f}, {row[f'{n}_high']:.3f}]" for n in names)
        shown.add_row(str(row["rank"]), str(row["policy"]), str(row["access"]), *cells, str(row["source"]))
    return shown
