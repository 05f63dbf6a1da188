"""``solarchain-eval bench``: throughput figures."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from . import app
from .common import console, err_console, reports_errors


@app.command("bench")
@reports_errors
def bench(
    data: Optional[Path] = typer.Option(None, "--data", help="Dataset directory (default: the embedded default dataset)."),
    steps: int = typer.Option(200_000, min=1000, help="Steps per repeat for the single env."),
    num_envs: int = typer.Option(1024, min=1, help="Sub-environments of the vector env."),
    calls: int = typer.Option(600, min=25, help="Vector-env step calls per repeat."),
    repeats: int = typer.Option(5, min=1, help="Repeats per figure (median and best are reported)."),
    skip_evaluation: bool = typer.Option(False, help="Skip timing the 1,620-episode baseline evaluation."),
) -> None:
    """Throughput of the single env, the vector env and the evaluation runner.

    Measures (a) one env through gym.make with random actions, resets included, (b) the native
    vector env at --num-envs sub-environments, (c) evaluating 1,620 baseline episodes with output
    files. Each figure is repeated; median and best are shown (shared machines are noisy).
    Targets on a 2-core machine: (a) >= 50,000 steps/s, (b) >= 3,000,000 env-steps/s, (c) < 10 s.
    """
    from .. import bench as measure
    from ..data.default import default_dataset_dir

    data_dir = data or default_dataset_dir()
    measure.warm_table(data_dir)
    results = []
    err_console.print("measuring the single env...")
    results.append((measure.single_env_steps_per_s(data_dir, steps, repeats), 50_000, True))
    err_console.print("measuring the vector env...")
    results.append((measure.vector_env_steps_per_s(data_dir, num_envs, calls, repeats), 3_000_000, True))
    if not skip_evaluation:
        err_console.print("timing the baseline evaluation...")
        results.append((measure.evaluation_seconds(data_dir, max(1, min(repeats, 3))), 10.0, False))
    table = Table(title=f"throughput on {data_dir}", title_justify="left")
    for column in ("measurement", "median", "best", "unit", "target"):
        table.add_column(column, justify="left" if column in ("measurement", "unit") else "right")
    for result, target, higher_is_better in results:
        if higher_is_better:
            median, best, goal = f"{result.median:,.0f}", f"{result.best:,.0f}", f">= {target:,.0f}"
        else:
            median, best, goal = f"{result.median:.2f}", f"{min(result.samples):.2f}", f"< {target:g}"
        table.add_row(result.name, median, best, result.unit, goal)
    console.print(table)

