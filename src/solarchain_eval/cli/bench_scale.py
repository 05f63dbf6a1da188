"""``solarchain-eval bench-scale``: dataset build, load and env throughput against scale."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from . import app
from .common import CliError, console, err_console, reports_errors


@app.command("bench-scale")
@reports_errors
def bench_scale(
    scales: str = typer.Option(
        "5x10,5x100,5x1000,50x1,50x10,50x100",
        "--scales",
        help="Comma-separated CITIESxNODES_PER_CITY pairs (synthetic cities and weather). "
        "Default: 50, 500 and 5,000 nodes over 5 and over 50 cities.",
    ),
    start: str = typer.Option("2026-04-01", help="First day of the built datasets."),
    end: str = typer.Option("2026-05-01", help="Day after the last one (default: a 30-day month, 720 hours)."),
    env_steps: int = typer.Option(20_000, min=1000, help="Single-env steps per repeat."),
    num_envs: int = typer.Option(256, min=1, help="Sub-environments of the vector env."),
    calls: int = typer.Option(200, min=25, help="Vector-env step calls per repeat."),
    repeats: int = typer.Option(3, min=1, help="Repeats per env figure (the median is shown)."),
    json_out: Path | None = typer.Option(None, "--json", help="Also write the figures to this JSON file."),
) -> None:
    """Scale benchmark: build, load and step synthetic datasets of growing size.

    For every CITIESxNODES pair: synthetic weather, the dataset build (all four CSVs written;
    time per node), loading it (validation and the hourly table), the single env's steps/s and
    the vector env's env-steps/s. Build time should grow about linearly in nodes; env steps/s
    should not depend on the node count (the env reads the hourly table, which aggregates the
    nodes). The 5,000-node build writes 3.6 million generation rows and takes minutes.
    """
    from ..perf.scale_bench import measure_scale, parse_scales

    try:
        pairs = parse_scales(scales)
    except ValueError as error:
        raise CliError(f"--scales: {error}") from None
    results = []
    for cities, nodes in pairs:
        err_console.print(f"building and measuring {cities} cities x {nodes} nodes = {cities * nodes:,} nodes...")
        results.append(
            measure_scale(
                cities, nodes, start=start, end=end, env_steps=env_steps, num_envs=num_envs, vector_calls=calls,
                repeats=repeats,
            )
        )  # fmt: skip
    table = Table(title="scale benchmark (synthetic weather)", title_justify="left")
    columns = ("cities", "nodes", "generation rows", "build s (CPU)", "build CPU ms/node", "load s (CPU)",
               "env steps/s", "vector env-steps/s")  # fmt: skip
    for column in columns:
        table.add_column(column, justify="right")
    for r in results:
        table.add_row(
            f"{r.cities}", f"{r.nodes:,}", f"{r.generation_rows:,}", f"{r.build_s:.1f} ({r.build_cpu_s:.1f})",
            f"{r.build_ms_per_node:.2f}", f"{r.load_s:.2f} ({r.load_cpu_s:.2f})", f"{r.env_steps_per_s:,.0f}",
            f"{r.vector_env_steps_per_s:,.0f}",
        )  # fmt: skip
    console.print(table)
    if json_out is not None:
        from ..common.atomic_files import atomic_write_text

        atomic_write_text(json_out, json.dumps([r.as_dict() for r in results], indent=2) + "\n")
