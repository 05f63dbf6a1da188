"""``solarchain-eval bench-train``: SB3 training steps/s per algorithm and the paper preset's wall time."""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Any

import typer
from rich.table import Table

from . import app
from .common import CliError, console, err_console, reports_errors

#: Targets on the 2-core reference machine with one torch thread (steps/s).


@app.command("bench-train")
@reports_errors
def bench_train(
    data: Path | None = typer.Option(None, "--data", help="Dataset directory (default: the embedded default dataset)."),
    algos: str = typer.Option("ppo,sac,dqn", "--algos", help="Comma-separated algorithms to measure."),
    repeats: int = typer.Option(3, "--repeats", min=1, help="Repeats per figure (median and best are reported)."),
    ceiling: bool = typer.Option(
        True, "--ceiling/--no-ceiling", help="Also measure SB3 on a trivial env (its own ceiling)."
    ),
    workers: int = typer.Option(2, "--workers", min=1, help="Workers for the paper-preset wall-time estimate."),
    from_root: Path | None = typer.Option(
        None, "--from-root", help="Estimate from the per-unit times of a finished grid run instead of measuring."
    ),
    backend: str = typer.Option(
        "sb3",
        "--backend",
        help="jax: also measure rejax training (same algorithms, same run) beside SB3, print the ratio "
        "and estimate the paper preset with the JAX backend. XLA settings come from XLA_FLAGS.",
    ),
    jax_seeds: int = typer.Option(1, "--jax-seeds", min=1, help="Seeds vmapped together in the JAX measurement."),
    chunk_steps: int | None = typer.Option(
        None,
        "--chunk-steps",
        min=0,
        help="jax: also measure what training in chunks costs: 3 chunks of this many env steps (0: each "
        "algorithm's default) with a checkpoint each, against the same steps in one call and rejax's own train, "
        "alternately (the grid's 3-seed groups, the paper's replay buffer).",
    ),
) -> None:
    """Measure steady-state SB3 training speed (one torch thread) per algorithm on this env and on
    a trivial env with the same spaces, then estimate the paper preset's wall time (300,000 steps,
    18 models, 54 evaluation units in 4 settings) on --workers workers by simulating the grid scheduler.

    Measured figures: docs/performance.md.
    """
    if backend not in ("sb3", "jax"):
        raise CliError(f"unknown backend '{backend}' (choose from sb3, jax)")
    if chunk_steps is not None and (backend != "jax" or from_root is not None):
        raise CliError("--chunk-steps measures JAX trainings: it needs --backend jax and no --from-root")
    from ..perf import train_bench as measure
    from ..perf.env_bench import Throughput
    from ..tasks.registry import get_task
    from ..training.sb3_trainer import check_algo

    if from_root is not None:
        try:
            times = measure.unit_times_from_root(from_root)
        except (OSError, ValueError, KeyError) as error:
            raise CliError(f"cannot read unit times from {from_root}: {error}") from None
    else:
        data_dir = get_task().data_dir(data, None)  # the solar market's dataset
        names = [check_algo(a) for a in algos.split(",") if a.strip()]
        table = Table(title="SB3 training throughput, one torch thread (steps/s)", title_justify="left")
        for column in ("algorithm", "median", "best", "trivial env median", "env share"):
            table.add_column(column, justify="left" if column == "algorithm" else "right")
        rates: dict[str, float] = {}
        cpu_rates: dict[str, list[float]] = {}
        for algo in names:
            steps = measure.DEFAULT_STEPS[algo]
            err_console.print(f"measuring {algo.upper()} ({repeats} × {steps:,} steps)...")
            cpu_rates[algo] = []
            result = measure.training_steps_per_s(
                algo, measure.solarchain_env(algo, data_dir), steps, repeats, cpu_rates=cpu_rates[algo]
            )
            rates[algo] = result.median
            trivial: Throughput | None = None
            if ceiling:
                mode = "discrete" if algo == "dqn" else "continuous"
                trivial = measure.training_steps_per_s(algo, measure.TrivialEnv(mode), steps, repeats)
            table.add_row(
                algo.upper(),
                f"{result.median:,.0f}",
                f"{result.best:,.0f}",
                f"{trivial.median:,.0f}" if trivial else "-",
                f"{max(1 - result.median / trivial.median, 0):.1%}" if trivial else "-",
            )
        console.print(table)
        err_console.print("timing the evaluation units...")
        times = measure.measured_unit_times(data_dir, rates)
    missing = [a for a in ("ppo", "sac", "dqn") if a not in times.steps_per_s]
    if missing and from_root is not None:
        raise CliError(f"the estimate needs all three algorithms; missing {', '.join(missing)}")
    if missing:  # --algos measured a subset: its figures stand, the preset cannot be estimated
        console.print(f"no paper estimate: it needs all three algorithms (missing {', '.join(missing)})")
    else:
        _print_estimate(times, workers)
    if backend == "jax" and from_root is None:
        from .bench_train_jax import bench_jax

        sb3_cpu = {a: statistics.median(r) for a, r in cpu_rates.items()}
        bench_jax(names, data_dir, repeats, times, sb3_cpu, workers, jax_seeds)
        if chunk_steps is not None:
            from .bench_train_jax import bench_chunks

            bench_chunks(names, data_dir, repeats, chunk_steps or None)


def _print_estimate(times: Any, workers: int) -> None:
    """The paper preset's estimated wall time from ``times`` (a ``bench_train.UnitTimes``)."""
    from ..perf.train_bench import estimate_paper_wall_time

    estimate = estimate_paper_wall_time(times, workers)
    console.print(f"paper preset on {workers} worker(s), from {times.source}:")
    console.print(
        "  steps/s used: "
        + ", ".join(f"{a.upper()} {r:,.0f}" for a, r in sorted(times.steps_per_s.items()))
        + f"; train-unit overhead {times.train_overhead_s:.1f} s; eval units "
        + ", ".join(f"{p} {s:.1f} s" for p, s in sorted(times.eval_s.items()))
    )
    console.print(
        f"  estimated wall time {estimate['wall_s'] / 3600:.2f} h; total CPU "
        f"{estimate['cpu_s'] / 3600:.2f} h, of which SAC training {estimate['train_sac_cpu_s'] / 3600:.2f} h"
    )
