"""``solarchain-eval compare``: two runs of the same episodes, metric by metric, with intervals."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from . import app
from .common import CliError, console, reports_errors

_FORMATS = {"cumulative_reward": ".2f"}  # others: 4 decimals


def _load(spec: str, option: str):
    """metrics.csv rows of every run dir / paper root listed in ``spec`` (comma-separated)."""
    import pandas as pd

    from ..evaluation.records import METRICS_FILE
    from ..experiments.layout import read_run_table

    frames = []
    for part in [p for p in spec.split(",") if p.strip()]:
        path = Path(part.strip())
        frame = read_run_table(path, METRICS_FILE)
        if frame.empty:
            raise CliError(f"{option}: {path} holds no {METRICS_FILE} (a run directory or a paper root)")
        frames.append(frame)
    if not frames:
        raise CliError(f"{option}: no run given")
    return pd.concat(frames, ignore_index=True)


@app.command("compare")
@reports_errors
def compare(
    base: str = typer.Argument(
        ..., metavar="BASE", help="The reference: run directories or paper roots, comma-separated."
    ),
    other: str = typer.Argument(
        ..., metavar="OTHER", help="The run compared with it (same episodes), comma-separated likewise."
    ),
    metrics: str = typer.Option(
        "cumulative_reward,physics_violation_rate,artificial_liquidity_MWh,mean_slippage",
        "--metrics",
        help="metrics.csv columns to compare, comma-separated.",
    ),
    resamples: int = typer.Option(2000, min=100, help="Bootstrap resamples per interval."),
    csv: Path | None = typer.Option(None, "--csv", help="Also write every row (with the interval) to this CSV file."),
) -> None:
    """Compare two runs of the same episodes: mean(OTHER) - mean(BASE) per policy, setting and metric.

    Each difference gets a 95 % cluster-bootstrap interval over start days, resampled jointly
    for both runs (a day that is hard for both cancels out). Use it to compare the SB3 and JAX
    backends, two configs or two code versions on the same grid; both sides must have evaluated
    the same run seeds and episodes for every policy and setting they share. A * marks an
    interval that excludes 0. See docs/jax.md#same-science-both-backends-at-a-reduced-budget.
    """
    from ..common.atomic_files import atomic_write_csv
    from ..report.compare import compare_runs
    from ..report.statistics import DEFAULT_SEED

    base_rows, other_rows = _load(base, "BASE"), _load(other, "OTHER")
    chosen = [m.strip() for m in metrics.split(",") if m.strip()]
    missing = [m for m in chosen if m not in base_rows.columns or m not in other_rows.columns]
    if missing or not chosen:
        raise CliError(f"--metrics: {', '.join(missing) or 'none given'} not in both runs' metrics.csv")
    try:
        table = compare_runs(base_rows, other_rows, chosen, n_resamples=resamples, seed=DEFAULT_SEED)
    except ValueError as error:
        raise CliError(str(error)) from None
    if table.empty:
        raise CliError("the two runs share no policy and setting")
    if csv is not None:
        atomic_write_csv(csv, table, index=False)
    shown = Table(title="mean(OTHER) - mean(BASE), 95 % interval over start days", title_justify="left")
    for column in ("setting", "policy", "metric", "BASE", "OTHER", "difference", "95 % interval", ""):
        shown.add_column(column, justify="left" if column in ("setting", "policy", "metric") else "right")
    for row in table.itertuples(index=False):
        f = _FORMATS.get(row.metric, ".4f")
        excludes_zero = row.low > 0 or row.high < 0
        shown.add_row(
            row.setting,
            row.policy,
            row.metric,
            format(row.base, f),
            format(row.other, f),
            format(row.difference, f),
            f"[{row.low:{f}}, {row.high:{f}}]",
            "*" if excludes_zero else "",
        )
    console.print(shown)
