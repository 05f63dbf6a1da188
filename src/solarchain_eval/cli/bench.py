"""``solarchain-eval bench``: throughput figures."""

from __future__ import annotations

import statistics
from pathlib import Path

import typer
from rich.table import Table

from ..tasks.base import has_jax_env
from ..tasks.governance_view import governance_view_of
from ..tasks.registry import DEFAULT_TASK, get_task
from . import app
from .common import CliError, console, err_console, reports_errors


@app.command("bench")
@reports_errors
def bench(
    data: Path | None = typer.Option(None, "--data", help="Dataset directory (default: the embedded default dataset)."),
    steps: int = typer.Option(200_000, min=1000, help="Steps per repeat for the single env."),
    num_envs: int = typer.Option(1024, min=1, help="Sub-environments of the vector env."),
    calls: int = typer.Option(600, min=25, help="Vector-env step calls per repeat."),
    repeats: int = typer.Option(5, min=1, help="Repeats per figure (median and best are reported)."),
    skip_evaluation: bool = typer.Option(False, help="Skip timing the 1,620-episode baseline evaluation."),
    backend: str = typer.Option(
        "numpy",
        "--backend",
        help="numpy, or jax: also the jitted JAX env (4,096 envs by default) beside the numpy vector env.",
    ),
    episodes: int = typer.Option(10, min=1, help="JAX backend: episodes per env per repeat."),
    jax_devices: int | None = typer.Option(
        None,
        "--jax-devices",
        min=1,
        help="JAX backend: devices to split the envs over. Default: every device; on a CPU, one XLA host "
        "device per core (XLA runs each device's program on one thread).",
    ),
    diagnostics: bool = typer.Option(
        False,
        "--diagnostics",
        help="Instead: time an agentic evaluation (rule planner and auditor; static, random, myopic; 30 episodes) "
        "with and without governance diagnostics and print the slowdown (docs/governance.md).",
    ),
    task: str = typer.Option(
        DEFAULT_TASK,
        "--task",
        help="The task whose environments are measured, and with --diagnostics governed (the evaluation timing "
        "is the solar market's).",
    ),
) -> None:
    """Throughput of the single env, the vector env and the evaluation runner.

    Measures (a) one env of --task with gym.make's wrappers and random actions, resets included
    (for another task than the solar market, beside the solar market's single env, repeats
    alternating, and the ratio of the two), (b) its vector env (the solar market's native one) at
    --num-envs sub-environments, (c) evaluating 1,620 baseline episodes with output files (the
    solar market only). Each figure is repeated; median and best are shown (shared machines are
    noisy). Measured figures: docs/performance.md.
    """
    from ..perf import env_bench as measure

    if backend not in ("numpy", "jax"):
        raise typer.BadParameter(f"--backend must be numpy or jax, not {backend!r}")
    market = get_task(task)
    if diagnostics:
        governance_view_of(market)  # a task without a governance view: one line
    if backend == "jax" and not has_jax_env(market):
        raise CliError(f"--backend jax: task {task!r} has no JAX environment")
    data_dir = market.data_dir(data, None)
    measure.warm_table(data_dir, task)
    if diagnostics:
        _bench_diagnostics(data_dir, repeats, task)
        return
    results = []
    if backend == "jax":
        _bench_jax(data_dir, 4096 if num_envs == 1024 else num_envs, calls, episodes, repeats, jax_devices, task)
        return
    ratio = None
    if task == DEFAULT_TASK:
        err_console.print("measuring the single env...")
        results.append((measure.single_env_steps_per_s(data_dir, steps, repeats, task), True))
    else:  # beside the solar market's single env, repeats interleaved: the ratio is the same run's
        err_console.print(f"measuring the single env of {task} and of {DEFAULT_TASK} (alternating)...")
        pair = measure.single_envs_steps_per_s(data_dir, steps, repeats, (task, DEFAULT_TASK))
        results += [(result, True) for result in pair]
        ratio = pair[0].median / pair[1].median
    err_console.print("measuring the vector env...")
    results.append((measure.vector_env_steps_per_s(data_dir, num_envs, calls, repeats, task), True))
    if task != DEFAULT_TASK:
        err_console.print(f"(the evaluation timing is the solar market's: skipped for task {task!r})")
    elif not skip_evaluation:
        err_console.print("timing the baseline evaluation...")
        results.append((measure.evaluation_seconds(data_dir, max(1, min(repeats, 3))), False))
    table = Table(title=f"throughput on {data_dir or task}", title_justify="left")
    for column in ("measurement", "median", "best", "unit"):
        table.add_column(column, justify="left" if column in ("measurement", "unit") else "right")
    for result, higher_is_better in results:
        if higher_is_better:
            median, best = f"{result.median:,.0f}", f"{result.best:,.0f}"
        else:
            median, best = f"{result.median:.2f}", f"{min(result.samples):.2f}"
        table.add_row(result.name, median, best, result.unit)
        if ratio is not None and result.name.endswith(f"task {DEFAULT_TASK}"):
            table.add_row(f"ratio single env {task} / {DEFAULT_TASK} (medians)", f"{ratio:.2f}x", "", "")
    console.print(table)


def _bench_diagnostics(data_dir: Path | None, repeats: int, task: str = DEFAULT_TASK) -> None:
    """Median seconds of the same agentic evaluation of ``task`` without and with diagnostics, and their ratio."""
    from ..experiments.governance import diagnostics_overhead

    err_console.print("timing an agentic evaluation without and with diagnostics (alternating)...")
    overhead = diagnostics_overhead(data_dir, repeats=repeats, task=task)
    table = Table(title=f"governance diagnostics overhead on {data_dir or task}", title_justify="left")
    for column in ("measurement", "median s", "best s"):
        table.add_column(column, justify="left" if column == "measurement" else "right")
    for name, samples in (("without diagnostics", overhead.without_s), ("with diagnostics", overhead.with_s)):
        table.add_row(name, f"{statistics.median(samples):.3f}", f"{min(samples):.3f}")
    table.add_row("ratio with / without (medians)", f"{overhead.ratio:.2f}x", "")
    console.print(table)


def host_device_count(devices: int | None) -> int:
    """Ask XLA for one CPU host device per core (or ``devices``), before JAX starts.

    XLA reads ``XLA_FLAGS`` once, when JAX initialises its backends; a flag already given by the
    user wins. Returns the count asked for (the devices JAX will report may differ when JAX was
    already initialised in this process, or on a GPU, whose devices are used instead).
    """
    import os
    import sys

    from ..common.cpus import available_cpus

    count = devices or len(available_cpus())
    flags = os.environ.get("XLA_FLAGS", "")
    if "jax" not in sys.modules and "xla_force_host_platform_device_count" not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={count}".strip()
    return count


def _bench_jax(
    data_dir: Path | None,
    num_envs: int,
    calls: int,
    episodes: int,
    repeats: int,
    devices: int | None,
    task: str = DEFAULT_TASK,
) -> None:
    """The numpy vector env and the JAX env at the same number of envs, and their ratio."""
    from ..perf import env_bench as measure

    host_device_count(devices)
    from ..perf.jax_env_bench import jax_env_steps_per_s

    err_console.print(f"measuring the numpy vector env ({num_envs} envs)...")
    numpy_result = measure.vector_env_steps_per_s(data_dir, num_envs, calls, repeats, task)
    err_console.print(f"compiling and measuring the JAX env ({num_envs} envs)...")
    try:
        jax_result = jax_env_steps_per_s(data_dir, num_envs, episodes, repeats, devices, task)
    except ValueError as error:
        raise CliError(f"--jax-devices: {error}") from None
    table = Table(title=f"env throughput on {data_dir or task}", title_justify="left")
    for column in ("measurement", "median", "best", "unit"):
        table.add_column(column, justify="left" if column in ("measurement", "unit") else "right")
    table.add_row(numpy_result.name, f"{numpy_result.median:,.0f}", f"{numpy_result.best:,.0f}", "env-steps/s")
    table.add_row(jax_result.name, f"{jax_result.median:,.0f}", f"{jax_result.best:,.0f}", "env-steps/s")
    ratio = jax_result.median / numpy_result.median
    table.add_row("ratio JAX / numpy (medians)", f"{ratio:.2f}x", "", "")
    console.print(table)
