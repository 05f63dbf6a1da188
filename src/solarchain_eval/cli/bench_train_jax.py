"""``bench-train --backend jax``: rejax training speed beside SB3's, and the JAX paper-preset estimate."""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

from rich.table import Table

from .common import CliError, console, err_console

#: Goals of the JAX backend on 2 CPU cores.


def bench_jax(
    names: list[str], data_dir: Path, repeats: int, sb3_times, sb3_cpu: dict[str, float], workers: int, seeds: int
) -> None:
    """Measure each algorithm with rejax, print it beside SB3's figure, then the paper estimate.

    Two ratios are printed: of wall-clock steps/s, and of steps per CPU second (XLA may use a
    second thread; on a loaded machine the CPU-second figure is the steadier one).
    """
    from ..experiments.grid import GridSpec
    from ..perf import train_bench as measure

    paper = GridSpec.from_preset("paper", backend="jax")
    pinned = _pin_before_jax_starts()
    try:
        from ..perf.jax_train_bench import DEFAULT_STEPS, describe_flags, jax_eval_unit_s, jax_training_steps_per_s
    except ImportError as error:
        raise CliError(str(error)) from None
    flags = describe_flags()
    where = f"JAX on CPU {pinned}, as a grid worker runs" if pinned is not None else "JAX unpinned"
    table = Table(
        title=f"JAX (rejax) vs SB3 training throughput, steps/s per model ({where}; "
        f"XLA_FLAGS={flags['XLA_FLAGS'] or '-'})",
        title_justify="left",
    )
    columns = ("algorithm", "SB3 median", "JAX median", "JAX best", "JAX / SB3", "per CPU-s: SB3", "JAX", "JAX / SB3")
    for column in (*columns, "compile s"):
        table.add_column(column, justify="left" if column == "algorithm" else "right")
    rates, cpu_based, evals, cpu_ratios, compiles = {}, {}, {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for algo in names:
            steps = DEFAULT_STEPS[algo]
            err_console.print(f"measuring {algo.upper()} with JAX (compile, then {repeats} × {steps:,} steps)...")
            model_dir = Path(tmp) / algo
            speed = jax_training_steps_per_s(
                algo, data_dir, steps, repeats, seeds=seeds, model_dir=model_dir, buffer_timesteps=paper.timesteps
            )
            rates[algo] = speed.throughput.median
            compiles[algo] = speed.compile_s
            evals[algo] = jax_eval_unit_s(algo, model_dir, data_dir, sb3_times.episodes)
            sb3, sb3_per_cpu = sb3_times.steps_per_s.get(algo), sb3_cpu.get(algo)
            jax_per_cpu = speed.steps_per_cpu_s
            cpu_based[algo] = jax_per_cpu / seeds
            cpu_ratios[algo] = jax_per_cpu / sb3_per_cpu if sb3_per_cpu else float("nan")
            table.add_row(
                algo.upper(),
                f"{sb3:,.0f}" if sb3 else "-",
                f"{speed.throughput.median:,.0f}",
                f"{speed.throughput.best:,.0f}",
                f"{speed.throughput.median / sb3:.2f}×" if sb3 else "-",
                f"{sb3_per_cpu:,.0f}" if sb3_per_cpu else "-",
                f"{jax_per_cpu:,.0f}",
                f"{cpu_ratios[algo]:.2f}×",
                f"{speed.compile_s:.1f} ({speed.cached_compile_s:.1f} cached)",
            )
    console.print(table)
    if "sac" in rates and "sac" in sb3_times.steps_per_s:
        ratio = rates["sac"] / sb3_times.steps_per_s["sac"]
        console.print(f"SAC: JAX {ratio:.2f}× SB3 in wall-clock steps/s, {cpu_ratios['sac']:.2f}× per CPU second")
    missing = [a for a in ("ppo", "sac", "dqn") if a not in rates]
    if missing:
        console.print(f"no JAX paper estimate: it needs all three algorithms (missing {', '.join(missing)})")
        return
    group_rates, group_cpu, group_compile = _seed_group_rates(
        names, data_dir, repeats, seeds, (rates, cpu_based, compiles), paper
    )
    for label, steps_per_s in (("wall-clock", group_rates), ("per-CPU-second", group_cpu)):
        times = replace(
            sb3_times,
            steps_per_s=steps_per_s,
            # one compilation per seed group (algorithm and setting: the settings compile apart)
            train_overhead_by_algo={a: sb3_times.train_overhead_s + c for a, c in group_compile.items()},
            eval_s={**sb3_times.eval_s, **evals},
            source=f"JAX {label} rates of {len(paper.seeds)}-seed groups",
        )
        estimate = measure.estimate_paper_wall_time(times, workers, paper)
        minutes = estimate["wall_s"] / 60
        console.print(
            f"paper preset with --backend jax on {workers} worker(s), from {label} rates: estimated wall time "
            f"{minutes:.1f} min; total CPU "
            f"{estimate['cpu_s'] / 60:.1f} min, of which SAC training {estimate['train_sac_cpu_s'] / 60:.1f} min"
        )
    console.print(
        "(the per-CPU-second estimate is what a machine with its cores to itself would take; "
        "the wall-clock one includes this run's load)"
    )


def _pin_before_jax_starts() -> int | None:
    """Run JAX on one CPU, as the grid's pinned workers do (:func:`~..experiments.pool.worker_cpus`).

    XLA starts its threads when JAX first runs; they inherit this thread's affinity. Unpinned, a
    JAX training keeps about a third of a second core busy with the same steps/s, which two
    workers sharing two cores would pay for. Returns the CPU, or None where nothing was pinned
    (JAX already started, one CPU only, or no affinity control).
    """
    import sys

    from ..common.cpus import available_cpus, can_pin, pin_to_cpu

    cpus = available_cpus()
    if "jax" in sys.modules or not can_pin() or len(cpus) < 2:
        return None
    pin_to_cpu(cpus[0])
    return cpus[0]


def _seed_group_rates(
    names: list[str], data_dir: Path, repeats: int, seeds: int, measured: tuple[dict, dict, dict], paper: Any
) -> tuple[dict[str, float], dict[str, float], dict[str, float]]:
    """Per-model steps/s (wall, per CPU second) and compile seconds at the seed groups of the
    grid ``paper`` (a ``GridSpec``).

    The JAX grid trains an algorithm's seeds in one vmap (docs/jax.md), so the estimate needs the
    rate at that group size; measured here unless ``--jax-seeds`` already was that size.
    """
    from ..perf.jax_train_bench import DEFAULT_STEPS, jax_training_steps_per_s

    group = len(paper.seeds)
    if seeds == group:
        return measured
    wall, per_cpu, compile_s = {}, {}, {}
    for algo in names:
        err_console.print(f"measuring {algo.upper()} with JAX, {group} seeds vmapped (the grid's seed groups)...")
        speed = jax_training_steps_per_s(
            algo, data_dir, DEFAULT_STEPS[algo], repeats, seeds=group, buffer_timesteps=paper.timesteps
        )
        wall[algo], per_cpu[algo] = speed.throughput.median, speed.steps_per_cpu_s / group
        compile_s[algo] = speed.compile_s
        console.print(
            f"{algo.upper()}, {group} seeds vmapped: {speed.throughput.median:,.0f} steps/s per model "
            f"({group * speed.throughput.median:,.0f} in total; {speed.steps_per_cpu_s:,.0f} per CPU second in total)"
        )
    return wall, per_cpu, compile_s


def bench_chunks(names: list[str], data_dir: Path, repeats: int, chunk_steps: int | None) -> None:
    """Steps/s per model of the chunked training against one call (``bench-train --chunk-steps``)."""
    from ..experiments.grid import GridSpec
    from ..perf.jax_train_bench import chunking_cost

    paper = GridSpec.from_preset("paper", backend="jax")
    table = Table(
        title=f"JAX training in chunks vs one call, steps/s per model ({len(paper.seeds)} seeds vmapped, "
        f"replay buffer for {paper.timesteps:,} steps; median of {repeats})",
        title_justify="left",
    )
    columns = ("algorithm", "chunk steps", "chunked", "one call", "chunked / one call", "rejax train", "checkpoint")
    for column in columns:
        table.add_column(column, justify="left" if column == "algorithm" else "right")
    for algo in names:
        err_console.print(f"measuring {algo.upper()} in chunks against one call ({repeats} × 3 ways)...")
        cost = chunking_cost(
            algo, data_dir, repeats, chunk_steps=chunk_steps, seeds=len(paper.seeds), buffer_timesteps=paper.timesteps
        )
        table.add_row(
            algo.upper(),
            f"{cost.chunk_steps:,} × 3",
            f"{cost.chunked.median:,.0f}",
            f"{cost.one_loop.median:,.0f}",
            f"{cost.chunked.median / cost.one_loop.median:.3f}×",
            f"{cost.rejax_train.median:,.0f}",
            f"{cost.checkpoint_mb:,.0f} MB in {cost.checkpoint_s:.2f} s",
        )
    console.print(table)
