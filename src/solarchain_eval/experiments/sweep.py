"""``solarchain-eval sweep``: a sweep YAML expanded into units of the experiment grid, resumably.

A sweep root holds::

    ROOT/datasets/<key>/             one dataset per distinct set of build parameters (manifest last)
    ROOT/points/<point>/             one grid per point, laid out like a ``paper`` root (units,
                                     combined/<setting>/, paper_metadata.json with the point's axes)
    ROOT/results.csv                 the tidy table: a row per point x setting x policy x seed x episode
    ROOT/sensitivity/                each metric against each axis, and where a paper finding flips
    ROOT/sweep_metadata.json         the sweep, the points' status, versions (written last)

Every point's units are scoped into its directory (``points/<point>/train/...``) and all of them
go through one :func:`~.pool.run_units` call, so ``--workers``, Ray, ``--keep-going`` and
resume behave exactly as in ``paper``: a unit with a ``DONE`` marker is never run again, a point
whose grid identity changed is refused.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import pandas as pd

from ..common.atomic_files import atomic_write_json, atomic_write_with
from ..common.redaction import redact_command
from ..common.versions import git_commit, package_versions
from ..evaluation.records import ACTIONS_FILE, METRICS_FILE
from ..records_schema import EPISODE_COST
from ..tasks.base import episode_cost_fields
from ..tasks.dataset import ScenarioDatasetBuilder, dataset_of, has_dataset_builder
from ..tasks.registry import DEFAULT_TASK, get_task
from .combine import combine_setting
from .grid import GridSpec, Unit, plan_units, scoped
from .grid_root import (
    GridError,
    finished_units,
    grid_identity,
    identity_conflict,
    locked,
    make_executor,
    read_metadata,
    root_metadata,
    unit_task,
    write_metadata,
)
from .layout import combined_dir
from .pool import RunReport, run_units
from .sweep_spec import DATASET, Sweep, SweepDataset, SweepPoint, build_parameters
from .units import UnitResult, UnitTask
from .user_agents import GridPolicies, check_resolved, grid_policies

DATASETS_DIR = "datasets"
POINTS_DIR = "points"
RESULTS_FILE = "results.csv"
SWEEP_METADATA_FILE = "sweep_metadata.json"


@dataclass
class _PointRun:
    point: SweepPoint
    root: Path
    data_dir: Path
    spec: GridSpec
    identity: dict[str, Any]
    units: list[Unit]


@dataclass
class SweepOutcome:
    root: Path
    units: list[Unit]
    already_done: list[str]
    report: RunReport
    complete_points: list[str] = field(default_factory=list)
    all_points: bool = False  # every point complete (results.csv written; the CLI adds sensitivity/)
    results_rows: int = 0
    wall_s: float = 0.0


def _resolve(sweep: Sweep, path: str) -> Path:
    p = Path(path)
    return p if p.is_absolute() else (sweep.source.parent / p)


def build_point_dataset(
    sweep: Sweep, dataset: SweepDataset, out: Path, builder: ScenarioDatasetBuilder = DATASET
) -> Path:
    """Build one point's dataset into ``out`` (skipped when ``out`` holds a complete build).

    The build is the task's dataset builder's (:meth:`~solarchain_eval.tasks.dataset.ScenarioDatasetBuilder.build_point`;
    default: the solar market's, :data:`~.sweep_spec.DATASET`), with ``weather_cache`` relative to
    the YAML. For the solar market, the paper's cities use the cached weather file when it is given;
    any other cities (synthetic or listed) get synthetic weather.

    Raises
    ------
    GridError
        A build parameter the builder refuses (one line naming the sweep file).
    """
    if (out / builder.manifest).is_file():
        return out
    parameters = build_parameters(dataset, builder)
    if parameters.get("weather_cache") is not None:
        parameters["weather_cache"] = str(_resolve(sweep, parameters["weather_cache"]))
    try:
        builder.build_point(out, parameters)
    except ValueError as error:
        raise GridError(f"{sweep.source}: dataset: {error}") from None
    return out


def _point_spec(
    sweep: Sweep, point: SweepPoint, data_dir: Path, policies: GridPolicies, task: str = DEFAULT_TASK
) -> GridSpec:
    g = sweep.spec.grid
    try:
        spec = GridSpec(
            timesteps=g.timesteps,
            episodes=g.episodes,
            seeds=tuple(g.seeds),
            settings=tuple(g.settings),
            episode_seed_protocol=g.episode_seeds,
            data_dir=data_dir,
            config=point.config,
            checkpoint_every=g.checkpoint_every,
            preset="sweep",
            policies=policies.policies,
            policies_by_setting=policies.by_setting,
            lagrangian=point.lagrangian,
            agents=policies.agents,
            agent_args=policies.agent_args,
            vecnormalize=policies.vecnormalize,
            isolate=g.isolate,
            task=task,
        )
        spec.validate()
    except ValueError as error:
        raise GridError(f"{sweep.source}: grid: {error}") from None
    return spec


def sweep_policies(sweep: Sweep) -> GridPolicies:
    """``grid.policies`` as every point's grid takes them, user agents named (each built once);
    paths in agent specs and ``grid.vecnormalize`` are relative to the YAML.

    Raises
    ------
    GridError
        A spec that cannot be read or built, or a name that is taken (one line, naming the file).
    """
    g = sweep.spec.grid
    try:
        return grid_policies(
            g.policies,
            base=sweep.source.parent,
            config=sweep.points[0].config,
            agent_args=g.agent_args,
            vecnormalize=g.vecnormalize,
            isolate=g.isolate,
        )
    except (ValueError, FileNotFoundError) as error:
        raise GridError(f"{sweep.source}: grid.policies: {error}") from None


def check_sweep_agents(sweep: Sweep, policies: GridPolicies, data_dir: Path) -> None:
    """Try every user agent's first action on one of the sweep's datasets (a :class:`GridError` if it fails)."""
    try:
        check_resolved(
            policies.agents,
            config=sweep.points[0].config,
            agent_args=policies.agent_args,
            vecnormalize=policies.vecnormalize,
            data_dir=data_dir,
            run_seed=sweep.spec.grid.seeds[0],
            isolate=sweep.spec.grid.isolate,
        )
    except (ValueError, FileNotFoundError) as error:
        raise GridError(f"{sweep.source}: grid.policies on the dataset {data_dir}: {error}") from None


def _prepare_points(
    sweep: Sweep,
    root: Path,
    policies: GridPolicies,
    on_dataset: Callable[[str, bool], None] | None,
    command: list[str] | None,
    task: str = DEFAULT_TASK,
) -> list[_PointRun]:
    market = get_task(task)
    builder = dataset_of(market) if has_dataset_builder(market) else None
    tables: dict[str, dict[str, Any]] = {}
    data_dirs: list[Path] = []
    for point in sweep.points:
        if point.uses_existing_data:
            data_dir = _resolve(sweep, str(point.dataset.data)).resolve()
        else:
            if builder is None:  # the dataset section holds build parameters, and this task builds nothing
                raise GridError(
                    f"{sweep.source}: task {task!r} has no dataset builder; its sweep takes its dataset as dataset.data"
                )
            data_dir = (root / DATASETS_DIR / point.dataset_key).resolve()
            if str(data_dir) not in tables:
                fresh = not (data_dir / builder.manifest).is_file()
                if on_dataset is not None:  # before the build: a large one takes minutes
                    on_dataset(point.dataset_key, fresh)
                build_point_dataset(sweep, point.dataset, data_dir, builder)
        if str(data_dir) not in tables:
            tables[str(data_dir)] = market.provenance(market.load_data(data_dir))
        data_dirs.append(data_dir)
    # The user agents' first actions on every dataset (their shapes follow its cities), before any unit.
    for data_dir in dict.fromkeys(data_dirs):
        check_sweep_agents(sweep, policies, data_dir)
    runs = []
    for point, data_dir in zip(sweep.points, data_dirs, strict=True):
        dataset = tables[str(data_dir)]
        spec = _point_spec(sweep, point, data_dir, policies, task)
        identity = grid_identity(spec, dataset)
        point_root = root / POINTS_DIR / point.point_id
        if identity_conflict(point_root, identity) is not None:
            raise GridError.about(
                "{point_root} holds a different grid than point {point} of {source}; use another {opt_root}",
                point_root=point_root,
                point=point.point_id,
                source=sweep.source,
            )
        point_root.mkdir(parents=True, exist_ok=True)
        meta = root_metadata(spec, identity, dataset, data_dir, command, 1, None)
        meta["sweep_point"] = {"point": point.point_id, "values": point.values}
        write_metadata(point_root, {**meta, "status": "running", "complete": False})
        units = scoped(plan_units(spec), f"{POINTS_DIR}/{point.point_id}")
        runs.append(_PointRun(point, point_root, data_dir, spec, identity, units))
    return runs


def run_sweep(
    sweep: Sweep,
    root: Path,
    *,
    workers: int = 1,
    ray_address: str | None = None,
    keep_going: bool = False,
    on_plan: Callable[[list[Unit], list[str]], None] | None = None,
    on_result: Callable[[UnitResult], None] | None = None,
    on_dataset: Callable[[str, bool], None] | None = None,
    command: list[str] | None = None,
    ray_transfer: str = "auto",
    task: str | None = None,
) -> SweepOutcome:
    """Run (or resume) ``sweep`` into ``root``; see the module docstring.

    ``task``: the task every point trains and evaluates on, the one the sweep was loaded for
    (``load_sweep(path, task)``; None: that one). Its dataset builder builds the points' datasets
    (:mod:`~solarchain_eval.tasks.dataset`), and its declarations give the results' columns.

    Raises
    ------
    GridError
        Bad grid arguments, a task other than the sweep's, a point whose directory holds a
        different grid, or ``root`` busy.
    """
    started = time.perf_counter()
    if task is None:
        task = sweep.task
    elif task != sweep.task:
        raise GridError(f"{sweep.source}: loaded for task {sweep.task!r}, run for task {task!r}")
    if workers < 1:
        raise GridError.about("{opt_workers} must be at least 1, got {workers}", workers=workers)
    policies = sweep_policies(sweep)  # user agents named (and built once) before anything is written
    root = Path(root).resolve()
    root.mkdir(parents=True, exist_ok=True)
    with locked(root, "sweep"):
        runs = _prepare_points(sweep, root, policies, on_dataset, command, task)
        by_scope = {f"{POINTS_DIR}/{r.point.point_id}": r for r in runs}
        units = [u for r in runs for u in r.units]
        done: set[str] = set()
        for run in runs:  # each point's units are scoped into run.root, the sub-root finished_units checks
            done |= finished_units(root, run.units, run.spec)
        already = [u.name for u in units if u.name in done]
        if on_plan is not None:
            on_plan(units, already)

        def make_task(unit: Unit) -> UnitTask:
            run = by_scope[unit.scope]
            task = unit_task(run.spec, run.root, run.data_dir, run.identity, unit.unscoped(), command)
            return replace(task, unit=unit)

        executor = make_executor(ray_address, root, runs[0].data_dir, ray_transfer, workers)
        report = run_units(units, done, make_task, executor, keep_going=keep_going, on_result=on_result)
        outcome = SweepOutcome(root, units, already, report)
        for run in runs:
            if _finish_point(root, run, done):
                outcome.complete_points.append(run.point.point_id)
        outcome.all_points = len(outcome.complete_points) == len(runs)
        complete = [r.point for r in runs if r.point.point_id in outcome.complete_points]
        results = tidy_results(sweep, root, complete, task)
        if not results.empty:
            atomic_write_with(root / RESULTS_FILE, lambda tmp: results.to_csv(tmp, index=False))
            outcome.results_rows = len(results)
        outcome.wall_s = time.perf_counter() - started
        _write_metadata(sweep, root, runs, outcome, command)
    return outcome


def _finish_point(root: Path, run: _PointRun, done: set[str]) -> bool:
    """Combine the point's settings when all of its units are done; True if the point is complete."""
    complete = all(u.name in done for u in run.units)
    meta = read_metadata(run.root) or {}
    if complete:
        combined = {}
        for setting in run.spec.settings:
            evals = [u for u in run.units if u.kind == "eval" and u.setting == setting]
            combined[setting] = combine_setting(run.root, setting, [u.directory(root) for u in evals])
        meta.update({"combined": combined})
    meta.update({"status": "complete" if complete else "incomplete", "complete": complete})
    write_metadata(run.root, meta)
    return complete


_EPISODE = ["policy", "setting", "run_seed", "episode"]


def tidy_results(sweep: Sweep, root: Path, points: list[SweepPoint], task: str | None = None) -> pd.DataFrame:
    """One row per point x setting x policy x seed x episode: the axes' values, the task's
    metrics (``metrics.csv``'s columns, its declarations), and ``episode_cost`` = Σ_t (V_t + A_t),
    summed from the per-step records' fields the task names
    (:func:`~solarchain_eval.tasks.base.episode_cost_fields`; no column when it names none).
    ``task`` None: the sweep's."""
    fields = episode_cost_fields(get_task(task or sweep.task))
    frames = []
    for point in points:
        for setting in sweep.spec.grid.settings:
            folder = combined_dir(root / POINTS_DIR / point.point_id, setting)
            frame = pd.read_csv(folder / METRICS_FILE)
            if fields:
                steps = pd.read_csv(folder / ACTIONS_FILE, usecols=[*_EPISODE, *fields])
                total = steps[fields[0]]
                for name in fields[1:]:  # added step by step, in order (the solar results' bytes: V + A)
                    total = total + steps[name]
                steps[EPISODE_COST] = total
                cost = steps.groupby(_EPISODE, sort=False)[EPISODE_COST].sum().reset_index()
                frame = frame.merge(cost, on=_EPISODE, how="left", validate="one_to_one")
            head = {"point": point.point_id, "cost_limit": point.lagrangian.cost_limit}
            head.update({a: _cell(point.values[a]) for a in sweep.axes})
            frames.append(pd.concat([pd.DataFrame([head] * len(frame)), frame], axis=1))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _cell(value: Any) -> Any:
    return json.dumps(value) if isinstance(value, (list, dict)) else value


def _write_metadata(sweep: Sweep, root: Path, runs: list[_PointRun], outcome: SweepOutcome, command) -> None:
    failed = {r.unit: r.error for r in outcome.report.failed}
    atomic_write_json(
        root / SWEEP_METADATA_FILE,
        {
            "sweep_file": str(sweep.source),
            "sweep": sweep.identity(),
            "axes": list(sweep.axes),
            "points": {
                r.point.point_id: {
                    "values": r.point.values,
                    "data_dir": str(r.data_dir),
                    "complete": r.point.point_id in outcome.complete_points,
                    "units": len(r.units),
                }
                for r in runs
            },
            "failed_units": failed,
            "complete": outcome.all_points,
            "results_rows": outcome.results_rows,
            "wall_s": round(outcome.wall_s, 3),
            "command": redact_command(command or []),
            "git_commit": git_commit(),
            "package_versions": package_versions(),
        },
    )


__all__ = ["SweepOutcome", "build_point_dataset", "run_sweep", "sweep_policies", "tidy_results"]
