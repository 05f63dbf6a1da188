"""``solarchain-eval sweep``: scenario, reward-weight and scale sweeps on the experiment grid."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.text import Text

from ..experiments.grid import Unit
from ..experiments.grid_root import GridError
from ..experiments.sweep_spec import SweepError, load_sweep
from ..experiments.units import UnitResult
from ..tasks.registry import DEFAULT_TASK, get_task
from . import app
from .common import cli_error, console, err_console, invoked_command, register_user_error, reports_errors

# Registered here too: the CLI imports only the running command's module.
register_user_error(SweepError, GridError)


@app.command("sweep")
@reports_errors
def sweep(
    spec_file: Path = typer.Argument(
        ..., metavar="SWEEP.yaml", help="The sweep: grid, dataset, axes (docs/stress.md)."
    ),
    out: Path = typer.Option(..., "--out", help="The sweep root (created; re-run the same command to resume)."),
    workers: int = typer.Option(1, "--workers", min=1, help="Local worker processes (one torch thread each)."),
    ray_address: str | None = typer.Option(
        None, "--ray-address", help="Run units as Ray tasks: auto, ray://host:port, or local (needs the ray extra)."
    ),
    keep_going: bool = typer.Option(False, "--keep-going", help="Record failing units and carry on with the others."),
    task: str = typer.Option(
        DEFAULT_TASK,
        "--task",
        help="The task every point trains and evaluates on (default: the solar market); the dataset section "
        "and axes are its dataset builder's build parameters.",
    ),
) -> None:
    """Run a sweep: every combination of the YAML's axes is one grid of the `paper` runner.

    Axes: dataset scenario (fdia_rate, fdia_pattern, fdia_severity, fdia_burst_hours,
    nodes_per_city, cities = a number of synthetic cities), reward weights (lambda_p, lambda_d,
    lambda_j, lambda_u, lambda_f) and the PPO-Lagrangian constraint (cost_limit,
    multiplier_lr); grid.policies lists the policies and algorithms every point runs, and agents
    of your own as agent specs (with grid.agent_args and grid.vecnormalize), evaluated only.

    Writes ROOT/datasets/, ROOT/points/<point>/ (each a paper root), ROOT/results.csv (a row per
    point x setting x policy x seed x episode) and ROOT/sensitivity/ (each metric against each
    axis with cluster-bootstrap intervals, and findings.csv: where a paper finding holds or
    flips). Re-running the same command skips every finished unit.
    """
    task = get_task(task).name  # an unknown task is a one-line error before anything else
    sweep_spec = load_sweep(spec_file, task)
    err_console.print(
        f"sweep {spec_file}: {len(sweep_spec.points)} point(s) over axes {', '.join(sweep_spec.axes) or '(none)'} -> {out}",
        soft_wrap=True,
    )
    from ..experiments.ray_executor import RayUnavailableError
    from ..experiments.sweep import RESULTS_FILE, run_sweep

    def on_dataset(key: str, fresh: bool) -> None:
        err_console.print(f"dataset {key}: {'building...' if fresh else 'already built'}", soft_wrap=True)

    state = {"total": 0, "done": 0}

    def on_plan(units: list[Unit], already: list[str]) -> None:
        state.update(total=len(units), done=len(already))
        err_console.print(f"{len(units)} units, {len(already)} already done (skipped)", soft_wrap=True)

    def on_result(result: UnitResult) -> None:
        state["done"] += 1
        count = f"[{state['done']}/{state['total']}] "
        if result.ok:
            err_console.print(
                Text.assemble(count, ("done", "green"), f" {result.unit} ({result.wall_s:.1f} s)"), soft_wrap=True
            )
        else:
            err_console.print(
                Text.assemble(count, ("FAILED", "bold red"), f" {result.unit}: {result.error}"), soft_wrap=True
            )

    try:
        outcome = run_sweep(
            sweep_spec,
            out,
            workers=workers,
            ray_address=ray_address,
            keep_going=keep_going,
            on_plan=on_plan,
            on_result=on_result,
            on_dataset=on_dataset,
            command=invoked_command(),
            task=task,
        )
    except RayUnavailableError as error:
        raise cli_error(error) from None
    done = len(outcome.complete_points)
    console.print(
        f"sweep root: {outcome.root} ({done} of {len(sweep_spec.points)} points complete, "
        f"{outcome.results_rows:,} result rows, {outcome.wall_s:.1f} s)",
        soft_wrap=True,
    )
    if outcome.all_points:
        # the sensitivity report reads the tidy results (the report layer sits above the experiments)
        import pandas as pd

        from ..report.sensitivity import write_sensitivity

        results = pd.read_csv(outcome.root / RESULTS_FILE)
        resamples = sweep_spec.spec.bootstrap_resamples
        write_sensitivity(results, sweep_spec.axes, outcome.root / "sensitivity", resamples, task)
        console.print(f"results: {outcome.root / RESULTS_FILE}; sensitivity: {outcome.root / 'sensitivity'}")
    if outcome.report.failed:
        for r in outcome.report.failed:
            err_console.print(f"  FAILED {r.unit}: {r.error} (log: {r.log})", soft_wrap=True)
        raise typer.Exit(1)
