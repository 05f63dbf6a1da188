"""Running one grid unit (in whatever process the executor chose) and its on-disk markers.

A unit directory is written in this order: ``unit.json`` (what the unit is), the outputs
(each file atomically), then the done-marker ``DONE`` (a small JSON with the unit's wall time and
the CPU time of the process that ran it).
``unit.log`` is an append-only, human-readable log (start, progress, result, traceback) that no
later stage reads. Redoing a unit first removes the outputs of an earlier, unfinished attempt;
a train unit keeps its files, so training resumes from its checkpoint (SB3's, or the JAX
backend's last chunk).
"""

from __future__ import annotations

import json
import os
import shutil
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..common.atomic_files import atomic_write_json, sha256_file
from ..config import BenchmarkConfig
from ..evaluation.settings import Setting
from ..governance.factory import AgenticOptions
from ..protocol import EPISODE_SEED_RULES
from ..tasks.registry import DEFAULT_TASK
from ..training.jax_progress import ChunkProgress
from ..training.lagrangian import LagrangianSettings
from ..training.sb3_session import set_torch_threads
from ..training.sb3_spec import CHECKPOINT_DIR, TrainSpec
from ..training.sb3_trainer import train
from .grid import Unit
from .layout import DONE_MARKER, seed_model_dir

UNIT_FILE = "unit.json"
UNIT_LOG = "unit.log"


@dataclass(frozen=True)
class UnitTask:
    """Everything a worker needs to run one unit (picklable; paths are the worker's)."""

    unit: Unit
    unit_dir: Path
    data_dir: Path
    config: BenchmarkConfig
    timesteps: int
    episodes: int
    episode_seed_protocol: str
    checkpoint_every: int
    no_physics_penalty: bool
    model_paths: dict[str, Path] = field(default_factory=dict)
    agentic: AgenticOptions | None = None  # set for units of an agentic setting
    identity: dict[str, Any] = field(default_factory=dict)
    command: tuple[str, ...] = ()
    lagrangian: LagrangianSettings | None = None  # train units of ppo-lag
    #: Eval units of a user agent: its spec text (built in the worker) and options.
    agent_spec: str | None = None
    agent_args: dict[str | None, dict[str, Any]] = field(default_factory=dict)
    vecnormalize: dict[str | None, Path] = field(default_factory=dict)
    isolate: bool = False  # eval units of a user agent: run it in a process of its own
    chunk_steps: int | None = None  # JAX train units: env steps per chunk (None: the algorithm's default)
    #: Eval units: their setting itself, since a spawned worker has not registered the user's settings.
    setting: Setting | None = None
    task: str = DEFAULT_TASK  # the task the unit trains or evaluates on


@dataclass(frozen=True)
class UnitProgress:
    """A running unit's news for the driver: a JAX training's chunk done, or a note (a resume)."""

    unit: str
    progress: ChunkProgress | None = None
    note: str | None = None


@dataclass(frozen=True)
class UnitResult:
    unit: str
    ok: bool
    wall_s: float
    error: str | None = None
    log: str | None = None
    #: CPU seconds (user + system, every thread) the unit's process spent on it; None if unknown.
    cpu_s: float | None = None


def read_done(unit_dir: Path) -> dict[str, Any] | None:
    """The done-marker's content, or None if the unit is not done."""
    path = Path(unit_dir) / DONE_MARKER
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except ValueError:
        return {}


def write_done(unit_dir: Path, unit: str, wall_s: float, cpu_s: float | None = None) -> Path:
    """Mark a unit done, recording its wall time and (when known) its CPU time in seconds.

    Both cover this attempt only: a train unit resumed from a checkpoint records the last attempt
    (its ``train_metadata.json`` holds the training's wall time over every attempt).
    """
    finished = datetime.now(UTC).isoformat(timespec="seconds")
    marker: dict[str, Any] = {"unit": unit, "wall_s": round(wall_s, 3)}
    if cpu_s is not None:
        marker["cpu_s"] = round(cpu_s, 3)
    return atomic_write_json(Path(unit_dir) / DONE_MARKER, {**marker, "finished_at": finished})


def undo(unit_dir: Path) -> None:
    """Mark a unit as not done (its outputs are replaced when it is redone)."""
    (Path(unit_dir) / DONE_MARKER).unlink(missing_ok=True)


def clear_for_redo(unit: Unit, unit_dir: Path) -> None:
    """Remove the outputs of an unfinished earlier attempt.

    A train unit keeps everything: :func:`~solarchain_eval.training.sb3_trainer.train` resumes from the
    checkpoint (or finds the training finished) and replaces its outputs itself.
    """
    if not unit_dir.is_dir() or unit.kind == "train":
        return
    for path in unit_dir.iterdir():
        if path.name == UNIT_LOG:
            continue
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)


def model_digest(paths: dict[str, Path]) -> dict[str, str]:
    return {name: sha256_file(path) for name, path in sorted(paths.items())}


class _UnitLog:
    def __init__(self, path: Path) -> None:
        self.path = path

    def write(self, message: str) -> None:
        stamp = datetime.now().isoformat(timespec="seconds")
        # Reopened per line: publishing an eval unit renames the directory under us.
        with open(self.path, "a", encoding="utf-8") as handle:
            handle.write(f"{stamp} {message}\n")

    def close(self) -> None:
        return None


def execute_unit(
    task: UnitTask, *, mark_done: bool = True, on_progress: Callable[[UnitProgress], None] | None = None
) -> UnitResult:
    """Run one unit into ``task.unit_dir``; never raises for a failing unit.

    Parameters
    ----------
    task : UnitTask
    mark_done : bool
        Write ``DONE`` at the end (False when the caller moves the files elsewhere first).
    on_progress : callable, optional
        Receives a :class:`UnitProgress` after each chunk of a JAX train unit (and its notes);
        ``unit.log`` gets the same lines either way.

    Returns
    -------
    UnitResult
        ``ok`` False with the error's last line; the traceback is in ``unit.log``.
    """
    unit, unit_dir = task.unit, Path(task.unit_dir)
    unit_dir.mkdir(parents=True, exist_ok=True)
    clear_for_redo(unit, unit_dir)
    log = _UnitLog(unit_dir / UNIT_LOG)
    log.write(f"start {unit.name} (pid {os.getpid()})")
    started = time.perf_counter()
    # The worker process runs one unit at a time, so its CPU clock's advance is this unit's.
    cpu_started = time.process_time()
    try:
        set_torch_threads(1)
        atomic_write_json(unit_dir / UNIT_FILE, {"unit": unit.name, **task.identity})
        if unit.kind == "train":
            _train_unit(task, log, on_progress)
        else:
            _evaluate_unit(task)
        wall_s = time.perf_counter() - started
        cpu_s = time.process_time() - cpu_started
        if mark_done:
            write_done(unit_dir, unit.name, wall_s, cpu_s)
        log.write(f"done in {wall_s:.1f} s ({cpu_s:.1f} CPU s)")
        return UnitResult(unit.name, True, wall_s, log=str(unit_dir / UNIT_LOG), cpu_s=cpu_s)
    except Exception as error:  # a failing unit is reported, not raised: the grid decides
        log.write(f"FAILED: {type(error).__name__}: {error}\n{traceback.format_exc()}")
        message = f"{type(error).__name__}: {error}".strip().splitlines()[-1]
        return UnitResult(unit.name, False, time.perf_counter() - started, message, str(unit_dir / UNIT_LOG))
    finally:
        log.close()


def _train_unit(task: UnitTask, log: _UnitLog, on_progress: Callable[[UnitProgress], None] | None) -> None:
    unit = task.unit
    if unit.backend == "jax":
        return _train_jax_unit(task, log, on_progress)
    spec = TrainSpec(
        algo=unit.policy,
        seed=unit.seed,
        timesteps=task.timesteps,
        no_physics_penalty=task.no_physics_penalty,
        data_dir=task.data_dir,
        config=task.config,
        checkpoint_every=task.checkpoint_every,
        lagrangian=task.lagrangian,
        task=task.task,
    )
    tenth = max(task.timesteps // 10, 1)
    reported = [0]

    def progress(steps: int) -> None:
        if steps - reported[0] >= tenth:
            log.write(f"trained {steps:,} / {task.timesteps:,} steps")
            reported[0] = steps

    outcome = train(spec, task.unit_dir, on_progress=progress, command=list(task.command))
    if outcome.resumed_from:
        log.write(f"resumed from checkpoint(s) at step {outcome.resumed_from}")
    log.write(f"{outcome.timesteps_done:,} steps at {outcome.steps_per_s:,.0f} steps/s")


def _train_jax_unit(task: UnitTask, log: _UnitLog, on_progress: Callable[[UnitProgress], None] | None) -> None:
    """A seed group with the JAX backend, one vmap, each model in ``seed_<s>/``; trained in
    chunks with a checkpoint after each in ``checkpoints/``, so a redone unit continues from
    its last chunk."""
    from ..training.jax_trainer import JaxTrainSpec, train_jax

    unit = task.unit
    seeds = unit.seed_group or (unit.seed,)
    spec = JaxTrainSpec(
        unit.policy,
        seeds,
        task.timesteps,
        task.no_physics_penalty,
        task.data_dir,
        task.config,
        task.chunk_steps,
        task=task.task,
    )
    out_dirs = {seed: seed_model_dir(task.unit_dir, seed) for seed in seeds}
    for directory in out_dirs.values():
        directory.mkdir(parents=True, exist_ok=True)

    def report(progress: ChunkProgress) -> None:
        log.write(f"trained {progress.describe()}")
        if on_progress is not None:
            on_progress(UnitProgress(unit.name, progress=progress))

    def note(text: str) -> None:
        log.write(text)
        if on_progress is not None:
            on_progress(UnitProgress(unit.name, note=text))

    outcome = train_jax(
        spec,
        out_dirs,
        on_progress=report,
        on_note=note,
        command=list(task.command),
        checkpoint_dir=task.unit_dir / CHECKPOINT_DIR,
    )
    if outcome.already_complete:
        log.write("the finished training was already there")
    else:
        log.write(f"jax: compiled in {outcome.compile_s:.1f} s, trained at {outcome.steps_per_s:,.0f} steps/s")


def _evaluate_unit(task: UnitTask) -> None:
    from ..evaluation.run_spec import EvaluationSpec
    from ..evaluation.runner import run_evaluation

    unit = task.unit
    # Only another task is named: the evaluation of a solar unit is the one before tasks.
    named = {"task": task.task} if task.task != DEFAULT_TASK else {}
    spec = EvaluationSpec(
        policies=[task.agent_spec or unit.policy],
        run_seeds=[unit.seed],
        episodes=task.episodes,
        data_dir=task.data_dir,
        no_physics_penalty=task.no_physics_penalty,
        config=task.config,
        models=dict(task.model_paths),
        episode_seeds=EPISODE_SEED_RULES[task.episode_seed_protocol],
        agentic=task.agentic,  # the Planner/Auditor layer in the agentic settings
        setting_label=unit.setting,
        setting=task.setting,
        agent_args=dict(task.agent_args),
        vecnormalize=dict(task.vecnormalize),
        isolate=task.isolate,
        **named,
    )
    if spec.setting != unit.setting:
        raise ValueError(f"unit {unit.name}: the task evaluates setting {spec.setting!r}")
    # The unit directory is replaced as a whole; unit.json and unit.log are the grid's and carried over.
    run_evaluation(spec, task.unit_dir, command=list(task.command), overwrite=True, keep=(UNIT_FILE, UNIT_LOG))


def collect_files(unit_dir: Path) -> dict[str, bytes]:
    """The unit's output files (relative path -> bytes), for shipping them to another machine."""
    files: dict[str, bytes] = {}
    for path in sorted(Path(unit_dir).rglob("*")):
        rel = path.relative_to(unit_dir)
        if path.is_file() and rel.parts[0] != CHECKPOINT_DIR and not path.name.endswith(".partial"):
            files[rel.as_posix()] = path.read_bytes()
    return files
