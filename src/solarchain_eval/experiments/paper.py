"""The ``paper`` stage: run a grid into a paper root, resumably, then combine per setting.

Re-running the same command skips every unit with a ``DONE`` marker and redoes the rest (train
units resume from their last checkpoint). A root remembers what it was made with
(``paper_metadata.json`` → ``identity``: budgets, episode-seed protocol, dataset hashes, config);
running a different grid into it is an error, while adding seeds or settings extends it. An eval
unit of a learned policy records the sha256 of the model it used and is redone if that model
changed; an eval unit of a user agent records its spec, options and files (:mod:`.agents`) and
is redone if they changed. One run at a time may use a root (a lock file). The ``paper``
command writes the report after a complete grid.
"""

from __future__ import annotations

import fcntl
import json
import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..agents.checkpoints import ALGOS, MODEL_FILE, TRAINABLE_ALGOS
from ..common.atomic_files import atomic_write_json
from ..common.errors import NamesOptions, OptionsError
from ..common.redaction import redact_command
from ..common.versions import git_commit, package_versions
from ..data.default import resolve_data_dir
from ..data.provenance import dataset_provenance
from ..data.table import load_table
from ..evaluation.fingerprint import merge_fingerprints, protocol_id
from ..evaluation.records import METADATA_FILE
from ..evaluation.settings import KNOWN_SETTINGS, setting_has_physics_penalty
from ..protocol import independent_episode_seeds
from ..training.sb3_trainer import differences
from .combine import combine_setting
from .grid import GridSpec, Unit, eval_model_path, plan_units
from .layout import PAPER_METADATA_FILE
from .pool import Executor, InlineExecutor, LocalPool, RunReport, run_units
from .units import UNIT_FILE, UnitProgress, UnitResult, UnitTask, model_digest, read_done, undo
from .user_agents import absolute_paths, agent_identity, worker_spec


class GridError(NamesOptions, OptionsError, ValueError):
    """The grid cannot run as asked (a different grid in ROOT, a busy ROOT, bad arguments)."""


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
    return identity


def model_file(backend: str) -> str:
    """The model file a train unit of ``backend`` writes (the one its eval units load and hash)."""
    from ..agents.jax_checkpoint import JAX_MODEL_FILE

    return JAX_MODEL_FILE if backend == "jax" else MODEL_FILE


def _agentic_identity(spec: GridSpec) -> dict[str, Any]:
    """The Planner/Auditor configuration behind the agentic settings (not how LLM calls are cached)."""
    described = spec.agentic.describe()
    llm = described.get("llm")
    if llm:
        llm = {k: v for k, v in llm.items() if k in ("api", "model", "base_url", "temperature", "max_output_tokens")}
        if str(llm.get("base_url") or "").startswith("http://127.0.0.1:"):  # --llm-backend local: a new port each run
            llm["base_url"] = "http://127.0.0.1/v1"
    return {"planner": described["planner"], "auditor": described["auditor"], "llm": llm}


@contextmanager
def _locked(root: Path, command: str = "paper") -> Iterator[None]:
    """Hold ``root``'s lock (one ``command`` run per root at a time)."""
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


def _read_metadata(root: Path) -> dict[str, Any] | None:
    import json

    path = root / PAPER_METADATA_FILE
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except ValueError as error:
        raise GridError(f"{path} is not valid JSON ({error})") from None


def _recorded(root: Path, unit: Unit) -> dict[str, Any] | None:
    """The unit's ``unit.json`` (None if unreadable)."""
    import json

    try:
        return json.loads((unit.directory(root) / UNIT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _stale_eval(root: Path, unit: Unit, spec: GridSpec) -> bool:
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
    data_dir = resolve_data_dir(spec.data_dir, cfg.data_dir).resolve()
    table = load_table(data_dir)  # validates the dataset before any work
    dataset = dataset_provenance(table)
    identity = grid_identity(spec, dataset)
    with _locked(root):
        previous = _read_metadata(root)
        if previous is not None and previous.get("identity") != identity:
            diffs = differences(previous.get("identity") or {}, identity)
            raise GridError.about(
                "{root} holds a different grid ({diffs}); use another {opt_root}", root=root, diffs="; ".join(diffs[:5])
            )
        units = plan_units(spec)
        done = _finished_units(root, units, spec)
        already = [u.name for u in units if u.name in done]
        meta = _metadata(spec, identity, dataset, data_dir, command, workers, ray_address)
        atomic_write_json(root / PAPER_METADATA_FILE, {**meta, "status": "running", "complete": False})
        if on_plan is not None:
            on_plan(units, already)

        def make_task(unit: Unit) -> UnitTask:
            return _task(spec, root, data_dir, identity, unit, command)

        executor = _executor(ray_address, root, data_dir, ray_transfer, workers, on_progress)
        report = run_units(
            units, done, make_task, executor, keep_going=keep_going, on_result=on_result, on_start=on_start
        )
        outcome = PaperOutcome(root, units, already, report)
        _combine_and_record(spec, outcome, done, meta, started)
    return outcome


def _finished_units(root: Path, units: list[Unit], spec: GridSpec) -> set[str]:
    """Names of the units already done; an eval unit whose model or agent changed since is undone."""
    done = set()
    for unit in units:
        if read_done(unit.directory(root)) is None:
            continue
        if unit.kind == "eval" and _stale_eval(root, unit, spec):
            undo(unit.directory(root))
        else:
            done.add(unit.name)
    return done


def _executor(
    ray_address: str | None,
    root: Path,
    data_dir: Path,
    ray_transfer: str,
    workers: int,
    on_progress: Callable[[UnitProgress], None] | None = None,
) -> Executor:
    if ray_address:
        from .ray_executor import RayExecutor

        return RayExecutor(ray_address, root, data_dir, transfer=ray_transfer, workers=workers)
    return LocalPool(workers, on_progress=on_progress) if workers > 1 else InlineExecutor(on_progress)


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
    atomic_write_json(
        root / PAPER_METADATA_FILE,
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
    """``{"protocol": fingerprint, "protocol_id": id}`` of a setting's eval units (empty for units
    written before runs carried a fingerprint)."""
    fingerprints = []
    for directory in unit_dirs:
        meta = json.loads((Path(directory) / METADATA_FILE).read_text(encoding="utf-8"))
        if "protocol" not in meta:
            return {}
        fingerprints.append(meta["protocol"])
    merged = merge_fingerprints(fingerprints)
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


def _task(
    spec: GridSpec, root: Path, data_dir: Path, identity: dict, unit: Unit, command: list[str] | None
) -> UnitTask:
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
        agentic=spec.agentic if (setting is not None and setting.agentic and unit.kind == "eval") else None,
        identity=unit_identity,
        command=tuple(command or sys.argv),
        lagrangian=spec.lagrangian if unit.policy == "ppo-lag" else None,
        # the spec as text (workers build the agent), named and with absolute paths
        agent_spec=worker_spec(unit.policy, agent) if agent is not None else None,
        agent_args=spec.agent_args if agent is not None else {},
        vecnormalize=absolute_paths(spec.vecnormalize) if agent is not None else {},
        isolate=spec.isolate and agent is not None,
        chunk_steps=spec.chunk_steps,
    )


def _metadata(
    spec: GridSpec,
    identity: dict,
    dataset: dict,
    data_dir: Path,
    command: list[str] | None,
    workers: int,
    ray_address: str | None,
) -> dict[str, Any]:
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
            "episode_seed_derivation": (
                "episode e of run seed s is reset with seed s + e"
                if spec.episode_seed_protocol == "paper"
                else (independent_episode_seeds.__doc__ or "").split("\n\n")[1].strip()
            ),
            "checkpoint_every": spec.checkpoint_every,
        },
        "data_dir": str(data_dir),
        "dataset": dataset,
        "execution": {"workers": workers, "ray_address": ray_address, "pid": os.getpid()},
        "command": redact_command(command or sys.argv),
        "updated_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "git_commit": git_commit(),
        "package_versions": package_versions(),
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


__all__ = ["GridError", "PaperOutcome", "grid_identity", "run_paper"]
