"""``solarchain-eval bench-suite``: the shipped suites' datasets built cold, and the held-out suite evaluated."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from . import app
from .common import CliError, console, err_console, reports_errors


def _met(wall_s: float, cpu_s: float, target_s: float | None, complete: bool) -> str:
    """Whether the wall and the CPU time are within the target; no verdict on a partial run."""
    if target_s is None:
        return ""
    if not complete:
        return "n/a (partial run)"
    return " / ".join("yes" if seconds <= target_s else "no" for seconds in (wall_s, cpu_s))


@app.command("bench-suite")
@reports_errors
def bench_suite(
    build: str | None = typer.Option(
        None,
        "--build",
        help="Comma-separated suites whose datasets are built (default: every shipped suite built offline, so "
        "not paper-cities).",
    ),
    suite: str = typer.Option("heldout", "--suite", help="The suite evaluated."),
    entries: int | None = typer.Option(
        None, "--entries", min=1, help="Only the first N entries of each suite (a quick check; no target then)."
    ),
    seeds: int = typer.Option(3, "--seeds", min=1, max=3, help="The first N of the paper's three run seeds."),
    episodes: int | None = typer.Option(
        None, "--episodes", min=1, help="Episodes per run seed (default: the configuration's, 30, as evaluate)."
    ),
    cache: Path | None = typer.Option(
        None, "--cache", help="Build into this empty directory and keep it (default: a temporary one)."
    ),
    out: Path | None = typer.Option(
        None, "--out", help="Write the evaluated suite's root here and keep it (default: a temporary one)."
    ),
    json_out: Path | None = typer.Option(None, "--json", help="Also write the figures to this JSON file."),
) -> None:
    """Time building every shipped offline suite's datasets into a fresh cache and evaluating Static, Random
    and Myopic over the held-out suite, each beside a reference on the paper's dataset.

    The build goes into an empty cache, as a first `evaluate --suite` builds; its reference is the
    paper's default dataset built once into another empty cache. The evaluation runs the default
    protocol of `evaluate --suite heldout` (3 run seeds x 30 episodes per entry, every file
    written); its reference is the same policies, seeds and episodes on the paper's dataset. Prints
    wall and CPU seconds, the ratios to the references and whether each is within its 60 s target
    (set for a 2-core machine). Measured figures: docs/performance.md.
    """
    from ..perf.suite_bench import BUILD_TARGET_S, EVALUATION_TARGET_S, measure_suite

    names = None if build is None else tuple(name.strip() for name in build.split(",") if name.strip())
    if names is not None and not names:
        raise CliError("--build: name one or more suites")
    err_console.print("building the suites' datasets into an empty cache, then evaluating; the references after...")
    if cache is not None and cache.exists() and (not cache.is_dir() or any(cache.iterdir())):
        raise CliError(f"--cache {cache}: give an empty or absent directory (the builds are timed cold)")
    try:
        result = measure_suite(build=names, suite=suite, entries=entries, seeds=seeds, episodes=episodes, cache=cache,
                               out=out)  # fmt: skip
    except ValueError as error:
        raise CliError(str(error)) from None
    table = Table(
        title=f"suites: {result.cpus} CPUs, load {result.load_1min[0]:.1f} before, {result.load_1min[1]:.1f} after",
        title_justify="left",
    )
    for column in ("measurement", "wall s", "CPU s", "ratio wall (CPU)", "target", "met: wall / CPU"):
        table.add_column(column, justify="left" if column == "measurement" else "right")
    build_row = f"{result.datasets_built} dataset(s) of {', '.join(result.built_suites)} built, empty cache"
    eval_row = (
        f"{'/'.join(result.policies)} over {result.suite} ({result.entries} entries x {result.run_seeds} seeds x "
        f"{result.episodes_per_seed} episodes: {result.episodes:,} episodes)"
    )
    rows = (
        (build_row, result.build_s, result.build_cpu_s, f"{result.build_ratio:.1f}x ({result.build_cpu_ratio:.1f}x)",
         BUILD_TARGET_S),
        ("  reference: the paper's dataset built, empty cache", result.reference_build_s,
         result.reference_build_cpu_s, "1x", None),
        (eval_row, result.evaluation_s, result.evaluation_cpu_s,
         f"{result.evaluation_ratio:.1f}x ({result.evaluation_cpu_ratio:.1f}x)", EVALUATION_TARGET_S),
        (f"  reference: the same on the paper's dataset ({result.reference_episodes:,} episodes)",
         result.reference_evaluation_s, result.reference_evaluation_cpu_s, "1x", None),
    )  # fmt: skip
    for name, wall_s, cpu_s, ratio, target in rows:
        shown = "" if target is None else f"{target:.0f} s"
        table.add_row(name, f"{wall_s:.1f}", f"{cpu_s:.1f}", ratio, shown, _met(wall_s, cpu_s, target, result.complete))
    console.print(table)
    console.print(f"suite protocol {result.suite_protocol_id}")
    if json_out is not None:
        from ..common.atomic_files import atomic_write_text

        atomic_write_text(json_out, json.dumps(result.as_dict(), indent=2) + "\n")
