"""A grid root, as ``paper`` and ``sweep`` share it: lock, identity, metadata, done units, tasks, executor.

A grid root (a ``paper`` root, or one point of a sweep) holds the units of one grid and its
``paper_metadata.json``. This module is everything both commands do to such a root:

- :func:`locked`: one run at a time per root (a lock file, ``ROOT/.lock``);
- :func:`grid_identity` and :func:`identity_conflict`: what every unit's result depends on, and
  whether the root already holds a grid with another identity;
- :func:`root_metadata`, :func:`read_metadata` and :func:`write_metadata`: the root's
  ``paper_metadata.json``;
- :func:`finished_units` and :func:`stale_eval`: which units are done, undoing an eval unit
  whose model or user agent changed since it ran;
- :func:`unit_task`: what a worker needs to run one unit;
- :func:`make_executor`: inline, a local process pool, or Ray.
"""

from __future__ import annotations

import fcntl
import json
import os
import sys
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..agents.checkpoints import ALGOS, MODEL_FILE, TRAINABLE_ALGOS
from ..common.atomic_files import atomic_write_json
from ..common.errors import NamesOptions, OptionsError
from ..common.redaction import redact_command
from ..common.versions import git_commit, package_versions
from ..evaluation.settings import KNOWN_SETTINGS, setting_has_physics_penalty
from ..protocol import episode_seed_derivation
from ..tasks.registry import DEFAULT_TASK
from ..training.sb3_trainer import differences
from .grid import GridSpec, Unit, eval_model_path
from .layout import PAPER_METADATA_FILE
from .pool import Executor, InlineExecutor, LocalPool
from .units import UNIT_FILE, UnitProgress, UnitTask, model_digest, read_done, undo
from .user_agents import absolute_paths, agent_identity, worker_spec


class GridError(NamesOptions, OptionsError, ValueError):
    """The grid cannot run as asked (a different grid in ROOT, a busy ROOT, bad arguments)."""


def grid_identity(spec: GridSpec, dataset: dict[str, Any]) -> dict[str, Any]:
    """What every unit's result depends on; a root accepts only grids with the same identity."""
    identity = {
        "timesteps": int(spec.timesteps),
        "episodes": int(spec.episodes),
        "episode_seed_protocol": spec.episode_seed_protocol,
        "dataset_sha256": dataset.get("files", {}),
        "config": spec.config.model_dump(mode="json"),
        "agentic": _agentic_identity(spec),
        # Only a JAX grid records its backend, so that the identity of existing SB3 roots is unchanged.
        **({"backend": spec.backend} if spec.backend != "sb3" else {}),
        # JAX train units train an algorithm's seeds together (one vmap): another layout of units.
        **({"train_units": "seed groups"} if spec.backend == "jax" else {}),
    }
    if spec.uses_lagrangian:  # only then: grids without ppo-lag keep their earlier identity
        identity["lagrangian"] = spec.lagrangian.describe()
    if spec.task != DEFAULT_TASK:  # only another task: solar roots (and the paper's protocol) keep their identity
        identity["task"] = spec.task
    return identity


def _agentic_identity(spec: GridSpec) -> dict[str, Any]:
    """The Planner/Auditor configuration behind the agentic settings (not how LLM calls are cached)."""
    described = spec.agentic.describe()
    llm = described.get("llm")
    if llm:
        llm = {k: v for k, v in llm.items() if k in ("api", "model", "base_url", "temperature", "max_output_tokens")}
        if str(llm.get("base_url") or "").startswith("http://127.0.0.1:"):  # --llm-backend local: a new port each run
            llm["base_url"] = "http://127.0.0.1/v1"
    return {"planner": described["planner"], "auditor": described["auditor"], "llm": llm}


def identity_conflict(root: Path, identity: dict[str, Any]) -> list[str] | None:
    """None when ``root`` holds no grid or a grid of this ``identity``; otherwise what differs
    (``key: old -> new`` lines).

    Raises
    ------
    GridError
        The root's metadata is not valid JSON.
    """
    previous = read_metadata(root)
    if previous is None or previous.get("identity") == identity:
        return None
    return differences(previous.get("identity") or {}, identity)


def model_file(backend: str) -> str:
    """The model file a train unit of ``backend`` writes (the one its eval units load and hash)."""
    from ..agents.jax_checkpoint import JAX_MODEL_FILE

    return JAX_MODEL_FILE if backend == "jax" else MODEL_FILE


@contextmanager
def locked(root: Path, command: str = "paper") -> Iterator[None]:
    """Hold ``root``'s lock (one ``command`` run per root at a time).

    Raises
    ------
    GridError
        Another run holds the lock.
    """
    handle = open(root / ".lock", "a+")  # noqa: SIM115 - held open for the lock's lifetime
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        raise GridError(f"another '{command}' run is using {root} (it holds {root / '.lock'})") from None
    try:
        yield
    finally:
        fcntl.flock(handle, fcntl.LOCK_UN)
        handle.close()


def read_metadata(root: Path) -> dict[str, Any] | None:
    """The root's ``paper_metadata.json`` (None when there is none yet).

    Raises
    ------
    GridError
        The file is not valid JSON.
    """
    path = root / PAPER_METADATA_FILE
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except ValueError as error:
        raise GridError(f"{path} is not valid JSON ({error})") from None


def write_metadata(root: Path, metadata: Mapping[str, Any]) -> None:
    """Write the root's ``paper_metadata.json`` (atomically: a reader sees the old or the new one)."""
    atomic_write_json(root / PAPER_METADATA_FILE, dict(metadata))


def root_metadata(
    spec: GridSpec,
    identity: dict,
    dataset: dict,
    data_dir: Path,
    command: list[str] | None,
    workers: int,
    ray_address: str | None,
) -> dict[str, Any]:
    """The metadata a run writes into its root before any unit: the identity, the grid as asked,
    the dataset, how it executes, the command (credentials redacted) and versions."""
    return {
        "identity": identity,
        "grid": {
            "preset": spec.preset,
            "timesteps": spec.timesteps,
            "episodes": spec.episodes,
            "seeds": list(spec.seeds),
            "settings": {s: [*spec.setting_policies(s), *spec.setting_agents(s)] for s in spec.settings},
            "agents": dict(spec.agents),
            "algorithms": list(ALGOS),
            "backend": spec.backend,
            "episode_seed_protocol": spec.episode_seed_protocol,
            "episode_seed_derivation": episode_seed_derivation(spec.episode_seed_protocol),
            "checkpoint_every": spec.checkpoint_every,
            "task": spec.task,
        },
        "data_dir": None if data_dir is None else str(data_dir),
        "dataset": dataset,
        "execution": {"workers": workers, "ray_address": ray_address, "pid": os.getpid()},
        "command": redact_command(command or sys.argv),
        "updated_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "git_commit": git_commit(),
        "package_versions": package_versions(),
    }


def _recorded(root: Path, unit: Unit) -> dict[str, Any] | None:
    """The unit's ``unit.json`` (None if unreadable)."""
    try:
        return json.loads((unit.directory(root) / UNIT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def stale_eval(root: Path, unit: Unit, spec: GridSpec) -> bool:
    """A done eval unit whose model (learned policy) or agent (user agent, or its door) changed since it was evaluated."""
    agent = spec.agent_spec(unit.policy)
    if agent is not None:
        recorded = _recorded(root, unit)
        current = agent_identity(unit.policy, agent, spec.agent_args, spec.vecnormalize)
        if recorded is None or recorded.get("agent") != current:
            return True
        return bool(recorded.get("isolate")) != spec.isolate
    if unit.policy not in TRAINABLE_ALGOS or not unit.depends_on:
        return False
    recorded = _recorded(root, unit)
    if recorded is None:
        return True
    model = eval_model_path(root, unit, spec.backend, model_file(spec.backend))
    return model is None or not model.is_file() or recorded.get("model_sha256") != model_digest({unit.policy: model})


def finished_units(root: Path, units: list[Unit], spec: GridSpec) -> set[str]:
    """Names of the units already done; an eval unit whose model or agent changed since is undone.

    A scoped unit (a sweep point's) is checked against its own sub-root ``root/<scope>``.
    """
    done = set()
    for unit in units:
        directory = unit.directory(root)
        if read_done(directory) is None:
            continue
        sub_root = Path(root) / unit.scope if unit.scope else Path(root)
        if unit.kind == "eval" and stale_eval(sub_root, unit.unscoped(), spec):
            undo(directory)
        else:
            done.add(unit.name)
    return done


def unit_task(
    spec: GridSpec, root: Path, data_dir: Path, identity: dict, unit: Unit, command: list[str] | None
) -> UnitTask:
    """What a worker needs to run ``unit`` of the grid ``spec`` in ``root`` (picklable)."""
    setting = KNOWN_SETTINGS.get(unit.setting)
    no_physics = setting.no_physics_penalty if setting is not None else not setting_has_physics_penalty(unit.setting)
    models: dict[str, Path] = {}
    unit_identity: dict[str, Any] = {
        "grid": identity,
        "setting": unit.setting,
        "policy": unit.policy,
        "seed": unit.seed,
    }
    if unit.kind == "eval" and unit.depends_on:
        models = {unit.policy: eval_model_path(root, unit, spec.backend, model_file(spec.backend))}
        unit_identity["model_sha256"] = model_digest(models)
    agent = spec.agent_spec(unit.policy) if unit.kind == "eval" else None
    if agent is not None:
        unit_identity["agent"] = agent_identity(unit.policy, agent, spec.agent_args, spec.vecnormalize)
        if spec.isolate:  # the rows' access label differs: a unit run in-process is not reused
            unit_identity["isolate"] = True
    return UnitTask(
        unit=unit,
        unit_dir=unit.directory(root),
        data_dir=data_dir,
        config=spec.config,
        timesteps=spec.timesteps,
        episodes=spec.episodes,
        episode_seed_protocol=spec.episode_seed_protocol,
        checkpoint_every=spec.checkpoint_every,
        no_physics_penalty=no_physics,
        model_paths=models,
        # a setting that declares its Planner/Auditor options is run with them
        agentic=(setting.governance or spec.agentic)
        if (setting is not None and setting.agentic and unit.kind == "eval")
        else None,
        identity=unit_identity,
        command=tuple(command or sys.argv),
        lagrangian=spec.lagrangian if unit.policy == "ppo-lag" else None,
        # the spec as text (workers build the agent), named and with absolute paths
        agent_spec=worker_spec(unit.policy, agent) if agent is not None else None,
        agent_args=spec.agent_args if agent is not None else {},
        vecnormalize=absolute_paths(spec.vecnormalize) if agent is not None else {},
        isolate=spec.isolate and agent is not None,
        chunk_steps=spec.chunk_steps,
        setting=setting if unit.kind == "eval" else None,
        task=spec.task,
    )


def make_executor(
    ray_address: str | None,
    root: Path,
    data_dir: Path,
    ray_transfer: str,
    workers: int,
    on_progress: Callable[[UnitProgress], None] | None = None,
) -> Executor:
    """Ray tasks when ``ray_address`` is given, else a local pool of ``workers`` processes (inline for one)."""
    if ray_address:
        from .ray_executor import RayExecutor

        return RayExecutor(ray_address, root, data_dir, transfer=ray_transfer, workers=workers)
    return LocalPool(workers, on_progress=on_progress) if workers > 1 else InlineExecutor(on_progress)


__all__ = [
    "GridError",
    "finished_units",
    "grid_identity",
    "identity_conflict",
    "locked",
    "make_executor",
    "model_file",
    "read_metadata",
    "root_metadata",
    "stale_eval",
    "unit_task",
    "write_metadata",
]
