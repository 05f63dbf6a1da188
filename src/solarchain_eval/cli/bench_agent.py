"""``solarchain-eval bench-agent``: the cost of evaluating your own agent, as an object, over HTTP and isolated."""

from __future__ import annotations

import statistics
from pathlib import Path

import typer
from rich.table import Table

from . import app
from .common import CliError, console, err_console, reports_errors


@app.command("bench-agent")
@reports_errors
def bench_agent(
    data: Path | None = typer.Option(None, "--data", help="Dataset directory (default: the embedded default dataset)."),
    seeds: int = typer.Option(3, "--seeds", min=1, max=3, help="The first N of the paper's three run seeds."),
    episodes: int = typer.Option(30, "--episodes", min=1, help="Episodes per run seed."),
    repeats: int = typer.Option(3, "--repeats", min=1, help="Repeats per figure (median and best are reported)."),
    url: str | None = typer.Option(
        None,
        "--url",
        help="Time this running agent server instead of the example one (its time to decide counts as overhead).",
    ),
) -> None:
    """Time evaluating the Static baseline, a Python agent object with the same action, that
    agent behind HTTP and that agent isolated (--isolate), on the paper's protocol (3 seeds x 30 episodes).

    Each evaluation writes a run directory (temporary). The HTTP agent asks the example agent
    server (examples/http_agent_server.py, started on a free port with Static's action) unless
    --url names another. Prints the Python agent's time relative to Static, the HTTP round
    trip's cost per step (wall time, and the CPU time of the benchmark's own process) and the
    isolated door's cost per step (its process started once, timed apart). Measured figures:
    docs/http_agents.md, docs/performance.md.
    """
    from ..agents.http_agent import HttpAgentError
    from ..perf.agent_bench import measure_agent_overhead
    from ..tasks.registry import get_task

    data_dir = get_task().data_dir(data, None)  # the solar market's dataset
    err_console.print(f"timing {repeats} x 4 evaluations of {seeds} seed(s) x {episodes} episodes...")
    try:
        result = measure_agent_overhead(data_dir, seeds=seeds, episodes=episodes, repeats=repeats, url=url)
    except (HttpAgentError, FileNotFoundError) as error:
        raise CliError(str(error)) from None
    table = Table(
        title=f"evaluating an agent: {seeds} seed(s) x {episodes} episodes = {result.steps:,} steps on {data_dir}",
        title_justify="left",
    )
    for column in ("measurement", "median", "best", "unit"):
        table.add_column(column, justify="left" if column in ("measurement", "unit") else "right")
    rows = (
        ("Static baseline (by name)", result.static_s),
        ("Python agent object (Static's action)", result.python_s),
        (f"HTTP agent ({result.url})", result.http_s),
        ("Python agent isolated (--isolate)", result.isolated_s),
    )
    for name, samples in rows:
        table.add_row(name, f"{statistics.median(samples):.3f}", f"{min(samples):.3f}", "s")
    table.add_row("ratio Python agent / Static (medians)", f"{result.python_over_static:.2f}x", "", "")
    table.add_row("HTTP overhead per step (medians)", f"{result.http_overhead_ms_per_step:.3f}", "", "ms/step")
    table.add_row(
        "  of which CPU time of this process (client)", f"{result.http_client_cpu_ms_per_step:.3f}", "", "ms/step"
    )
    table.add_row("ratio isolated / Python agent (medians)", f"{result.isolated_over_python:.2f}x", "", "")
    table.add_row("isolated overhead per step (medians)", f"{result.isolated_overhead_ms_per_step:.3f}", "", "ms/step")
    table.add_row("  of which CPU time of this process", f"{result.isolated_cpu_ms_per_step:.3f}", "", "ms/step")
    table.add_row("  start of the isolated agent's process (once)", f"{result.isolated_start_s:.3f}", "", "s")
    console.print(table)
