"""The ``paper`` stage: run a grid into a paper root, resumably, then combine per setting.

Re-running the same command skips every unit with a ``DONE`` marker and redoes the rest (train
units resume from their last checkpoint). A root remembers what it was made with
(``paper_metadata.json`` → ``identity``: budgets, episode-seed protocol, dataset hashes, config);
running a different grid into it is an error, while adding seeds or settings extends it. An eval
unit of a learned policy records the sha256 of the model it used and is redone if that model
changed; an eval unit of a user agent records its spec, options and files (:mod:`.agents`) and
is redone if they changed. One run at a time may use a root (a lock file). The ``paper``
command writes the report after a complete grid. The root machinery (lock, identity, metadata,
done units, tasks, executor) is :mod:`.grid_root`, shared with ``sweep``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..evaluation.fingerprint import protocol_id
from ..evaluation.records import METADATA_FILE
from ..evaluation.run_metadata import RunMetadata, RunMetadataError
from ..evaluation.run_metadata import setting_protocol as merge_setting_protocol
from ..tasks.registry import get_task
from .combine import combine_setting
from .grid import GridSpec, Unit, plan_units
from .grid_root import (
    GridError,
    finished_units,
    grid_identity,
    identity_conflict,
    locked,
    make_executor,
    model_file,
    root_metadata,
    unit_task,
    write_metadata,
)
from .pool import RunReport, run_units
from .units import UnitProgress, UnitResult, UnitTask, read_done


@dataclass
class PaperOutcome:
    root: Path
    units: list[Unit]
    already_done: list[str]
    report: RunReport
    combined: dict[str, dict[str, int]] = field(default_factory=dict)
    complete: bool = False
    wall_s: float = 0.0
    #: Each combined setting's protocol (see :func:`setting_protocol`).
    protocols: dict[str, dict[str, Any]] = field(default_factory=dict)


def run_paper(
    spec: GridSpec,
    root: Path,
    *,
    workers: int = 1,
    ray_address: str | None = None,
    keep_going: bool = False,
    on_start: Callable[[Unit], None] | None = None,
    on_result: Callable[[UnitResult], None] | None = None,
    on_plan: Callable[[list[Unit], list[str]], None] | None = None,
    command: list[str] | None = None,
    ray_transfer: str = "auto",
    on_progress: Callable[[UnitProgress], None] | None = None,
) -> PaperOutcome:
    """Run (or resume) the grid ``spec`` into ``root``; see the module docstring.

    ``on_progress`` receives the JAX train units' progress after each chunk (local executors;
    a Ray task's goes to its ``unit.log`` only).

    Raises
    ------
    GridError
        Bad arguments, a different grid already in ``root``, or ``root`` busy.
    """
    started = time.perf_counter()
    try:
        spec.validate()
    except ValueError as error:
        raise GridError(str(error)) from None
    if workers < 1:
        raise GridError.about("{opt_workers} must be at least 1, got {workers}", workers=workers)
    root = Path(root).resolve()
    root.mkdir(parents=True, exist_ok=True)
    cfg = spec.config
    task = get_task(spec.task)
    data_dir = task.data_dir(spec.data_dir, cfg)
    data_dir = None if data_dir is None else Path(data_dir).resolve()  # None: a task without a dataset
    table = task.load_data(data_dir)  # validates the dataset before any work
    dataset = task.provenance(table)
    identity = grid_identity(spec, dataset)
    with locked(root):
        diffs = identity_conflict(root, identity)
        if diffs is not None:
            raise GridError.about(
                "{root} holds a different grid ({diffs}); use another {opt_root}", root=root, diffs="; ".join(diffs[:5])
            )
        units = plan_units(spec)
        done = finished_units(root, units, spec)
        already = [u.name for u in units if u.name in done]
        meta = root_metadata(spec, identity, dataset, data_dir, command, workers, ray_address)
        write_metadata(root, {**meta, "status": "running", "complete": False})
        if on_plan is not None:
            on_plan(units, already)

        def make_task(unit: Unit) -> UnitTask:
            return unit_task(spec, root, data_dir, identity, unit, command)

        executor = make_executor(ray_address, root, data_dir, ray_transfer, workers, on_progress)
        report = run_units(
            units, done, make_task, executor, keep_going=keep_going, on_result=on_result, on_start=on_start
        )
        outcome = PaperOutcome(root, units, already, report)
        _combine_and_record(spec, outcome, done, meta, started)
    return outcome


def _combine_and_record(spec: GridSpec, outcome: PaperOutcome, done: set[str], meta: dict, started: float) -> None:
    """Combine every setting whose eval units are all done, then write the final paper metadata."""
    root, units, report = outcome.root, outcome.units, outcome.report
    protocols: dict[str, dict[str, Any]] = {}
    for setting in spec.settings:
        evals = [u for u in units if u.kind == "eval" and u.setting == setting]
        if all(u.name in done for u in evals):
            outcome.combined[setting] = combine_setting(root, setting, [u.directory(root) for u in evals])
            protocols[setting] = setting_protocol([u.directory(root) for u in evals])
    outcome.protocols = protocols
    outcome.complete = all(u.name in done for u in units)
    outcome.wall_s = time.perf_counter() - started
    status = "complete" if outcome.complete else ("stopped" if report.stopped else "incomplete")
    write_metadata(
        root,
        {
            **meta,
            "status": status,
            "complete": outcome.complete,
            "wall_s": round(outcome.wall_s, 3),
            "units": _unit_table(root, units, report),
            "combined": outcome.combined,
            # Each combined setting's protocol: the units' fingerprints, their run seeds united.
            "protocols": protocols,
            "combined_sha256": _combined_sha256(root, outcome.combined),
            "failed_units": [{"unit": r.unit, "error": r.error, "log": r.log} for r in report.failed],
        },
    )


def setting_protocol(unit_dirs: list[Path]) -> dict[str, Any]:
    """``{"protocol": fingerprint, "protocol_id": id}`` of a setting's eval units, merged as the
    leaderboard merges them (:func:`~solarchain_eval.evaluation.run_metadata.setting_protocol`);
    empty when a unit written before runs carried a fingerprint has none that can be computed."""
    runs = {str(d): RunMetadata.read(Path(d) / METADATA_FILE) for d in unit_dirs}
    try:
        merged = merge_setting_protocol(runs)
    except RunMetadataError:
        return {}
    return {"protocol": merged, "protocol_id": protocol_id(merged)}


def _combined_sha256(root: Path, settings: dict[str, Any]) -> dict[str, dict[str, str]]:
    """sha256 of each combined file, so that ``report`` can tell they are this grid's."""
    from ..common.atomic_files import sha256_file
    from .layout import combined_dir

    return {
        s: {
            p.name: sha256_file(p)
            for p in sorted(combined_dir(root, s).iterdir())
            if p.is_file() and not p.name.startswith(".")
        }
        for s in settings
    }


def _unit_table(root: Path, units: list[Unit], report: RunReport) -> dict[str, dict[str, Any]]:
    failed = {r.unit: r for r in report.failed}
    table: dict[str, dict[str, Any]] = {}
    for unit in units:
        marker = read_done(unit.directory(root))
        if marker is not None:
            table[unit.name] = {"status": "done", "wall_s": marker.get("wall_s"), "cpu_s": marker.get("cpu_s")}
        elif unit.name in failed:
            table[unit.name] = {"status": "failed", "error": failed[unit.name].error, "log": failed[unit.name].log}
        elif unit.name in report.blocked:
            table[unit.name] = {"status": "blocked"}
        elif unit.name in report.interrupted:
            table[unit.name] = {"status": "interrupted"}
        else:
            table[unit.name] = {"status": "pending"}
    return table


# GridError, grid_identity and model_file live in .grid_root; named here as before.
__all__ = ["GridError", "PaperOutcome", "grid_identity", "model_file", "run_paper", "setting_protocol"]
