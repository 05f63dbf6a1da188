"""rejax training on the JAX environment: all seeds of one algorithm in one jitted ``vmap``.

Hyperparameters follow the SB3 reference (docs/training.md; set in :mod:`.jax_algorithm`):
learning rate, batch size and γ from the config (3e-4, 64, 0.98), SB3's default network sizes
and other defaults where rejax has the same knob. The optimiser is SB3's (global-norm gradient clipping, SB3's Adam ε), and
so is PPO's value loss (unclipped); the remaining differences between the libraries are
listed in docs/jax.md. Each seed's acting network (actor, or
Q-network for DQN) is written to ``jax_model.msgpack`` in its directory with
``train_config.json`` and ``train_metadata.json`` beside it; ``evaluate --models`` loads it
through :class:`~solarchain_eval.agents.jax_checkpoint.JaxPolicy`. The training runs in
compiled chunks with progress and a checkpoint after each (:mod:`.jax_chunks`).
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import jax
import numpy as np
from flax import serialization

from ..agents.checkpoints import ACTION_MODES, TRAIN_CONFIG_FILE, TrainingError, check_algo, read_training_json
from ..agents.jax_checkpoint import JAX_MODEL_FILE
from ..common.atomic_files import atomic_write_bytes, atomic_write_json
from ..common.redaction import redact_command
from ..common.versions import git_commit, package_versions
from ..config import BenchmarkConfig
from ..tasks.base import has_jax_env, make_jax_env
from ..tasks.registry import DEFAULT_TASK, get_task

# The algorithm's pieces live in jax_algorithm (jax_chunks builds on them without importing this
# module); the `x as x` imports keep their names importable from here.
from .jax_algorithm import compile_training as compile_training
from .jax_algorithm import iteration_steps as iteration_steps
from .jax_algorithm import make_algo as make_algo
from .jax_algorithm import progress_chunks as progress_chunks
from .jax_algorithm import rejax_config
from .jax_algorithm import seed_keys as seed_keys
from .jax_algorithm import use_compilation_cache as use_compilation_cache
from .jax_alignment import SB3_ALIGNMENT
from .jax_chunks import CHECKPOINT_FILE, ChunkedTraining, config_sha256, run_chunks
from .jax_progress import ChunkProgress
from .sb3_spec import CHECKPOINT_DIR, TRAIN_METADATA_FILE, TrainSpec
from .sb3_trainer import differences


@dataclass(frozen=True)
class JaxTrainSpec:
    """One JAX training command: one model per seed, all seeds in one jitted ``vmap``.

    Parameters
    ----------
    algo : {"ppo", "sac", "dqn"}
    seeds : tuple of int
        One model per seed; each seed's ``jax.random.key`` drives its initialisation, env
        resets and exploration.
    timesteps : int
        Environment steps per model (PPO rounds up to whole 2,048-step rollouts, DQN to a
        multiple of its 4 envs, as SB3 does).
    no_physics_penalty : bool
    data_dir : path, optional
    config : BenchmarkConfig
    chunk_steps : int, optional
        Env steps per model in one compiled chunk, between which progress is reported and the
        train state checkpointed (default per algorithm:
        :data:`~.jax_progress.DEFAULT_CHUNK_STEPS`). It does not change the trained models.
    task : str
        The task to train on; it needs a JAX env (:func:`~solarchain_eval.tasks.base.make_jax_env`).
    """

    algo: str
    seeds: tuple[int, ...]
    timesteps: int
    no_physics_penalty: bool = False
    data_dir: Path | None = None
    config: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    chunk_steps: int | None = None
    task: str = DEFAULT_TASK

    def seed_spec(self, seed: int) -> TrainSpec:
        return TrainSpec(
            self.algo, seed, self.timesteps, self.no_physics_penalty, self.data_dir, self.config, task=self.task
        )


@dataclass(frozen=True)
class JaxTrainOutcome:
    algo: str
    seeds: tuple[int, ...]
    timesteps: int
    compile_s: float
    train_s: float
    model_paths: tuple[Path, ...]
    already_complete: bool = False
    resumed_from: int | None = None  # env steps per model at which this call resumed
    steps_trained: int = 0  # env steps per model trained by this call
    #: The final train states of all seeds, for tests and analyses (leading axis: the seed, except
    #: on leaves that are the same for every seed; see :class:`~.jax_chunks.ChunkRun`).
    states: Any = field(default=None, repr=False, compare=False)

    @property
    def steps_per_s(self) -> float:
        """Env steps of all seeds per second of training in this call (compilation excluded)."""
        return self.steps_trained * len(self.seeds) / max(self.train_s, 1e-9)


def no_jax_env(task: str) -> str:
    """The one-line error for a JAX training of a task that has no JAX env."""
    return f"task {task!r} has no JAX environment: train it with the sb3 backend"


def seed_dirs(out_dir: Path, seeds: tuple[int, ...]) -> dict[int, Path]:
    """Where each seed's model goes: ``out_dir`` itself for one seed, ``out_dir/seed_<s>`` for several."""
    out_dir = Path(out_dir)
    if len(seeds) == 1:
        return {int(seeds[0]): out_dir}
    return {int(s): out_dir / f"seed_{s}" for s in seeds}


def _identity(spec: JaxTrainSpec, seed: int, dataset: dict[str, Any]) -> dict[str, Any]:
    cfg = spec.seed_spec(seed).resolved_config()
    # Only another task is named, so that the identity (and resumes) of solar trainings is unchanged.
    named = {"task": spec.task} if spec.task != DEFAULT_TASK else {}
    return {
        **named,
        "algo": spec.algo,
        "backend": "jax",
        "seed": int(seed),
        "timesteps": int(spec.timesteps),
        "no_physics_penalty": bool(spec.no_physics_penalty),
        "action_mode": cfg.action_mode,
        "hyperparameters": json.loads(json.dumps(rejax_config(spec.algo, cfg, spec.timesteps), default=list)),
        "sb3_alignment": SB3_ALIGNMENT[spec.algo],
        "dataset_sha256": dataset.get("files", {}),
        "config": cfg.model_dump(mode="json"),
    }


def save_network(path: Path, algo: str, states: Any, index: int) -> Path:
    """Write seed ``index``'s acting network (what the policy adapter needs to act) as flax msgpack."""
    network = states.q_ts.params if algo == "dqn" else states.actor_ts.params
    one = jax.tree.map(lambda x: np.asarray(x[index]), network)
    return atomic_write_bytes(path, serialization.to_bytes(one))


def write_train_config(directory: Path, record: dict[str, Any]) -> Path:
    """``train_config.json``: the identity and the rejax settings the policy adapter rebuilds the network from."""
    return atomic_write_bytes(directory / TRAIN_CONFIG_FILE, json.dumps(record, indent=2, default=list).encode())


def _finished(directory: Path, identity: dict[str, Any], overwrite: bool) -> bool:
    """Whether ``directory`` holds this finished training; a different one is an error unless overwriting."""
    previous = read_training_json(directory / TRAIN_CONFIG_FILE)
    if previous is not None and previous.get("identity") != identity and not overwrite:
        diffs = differences(previous.get("identity") or {}, identity)
        raise TrainingError.about(
            "{out_dir} holds a different training ({diffs}); choose another output directory or pass {opt_overwrite}",
            out_dir=directory,
            diffs="; ".join(diffs[:6]),
        )
    meta = read_training_json(directory / TRAIN_METADATA_FILE) or {}
    same = previous is not None and previous.get("identity") == identity
    return same and bool(meta.get("complete")) and (directory / JAX_MODEL_FILE).is_file() and not overwrite


def train_jax(
    spec: JaxTrainSpec,
    out_dirs: dict[int, Path],
    *,
    on_progress: Callable[[ChunkProgress], None] | None = None,
    on_note: Callable[[str], None] | None = None,
    overwrite: bool = False,
    command: list[str] | None = None,
    checkpoint_dir: Path | None = None,
) -> JaxTrainOutcome:
    """Train ``spec.algo`` for every seed at once and write each seed's directory.

    Each ``out_dirs[seed]`` receives ``jax_model.msgpack`` (the acting network's parameters,
    flax msgpack), ``train_config.json`` (identity, rejax settings; written first) and
    ``train_metadata.json`` (times, steps/s, versions; ``"complete": true``, written last).
    A directory that already holds the same finished training is left as it is; when every
    seed's is, nothing is trained (``already_complete``).

    The training runs in chunks (:mod:`.jax_chunks`); after each, the whole train state is
    written to ``checkpoint_dir/jax_chunks.npz`` and ``on_progress`` receives a
    :class:`~.jax_progress.ChunkProgress`. A killed run resumes from that checkpoint when
    called again with the same spec (a checkpoint of another training is ignored, with a note
    to ``on_note``); the checkpoint is removed once the models are written.

    Parameters
    ----------
    checkpoint_dir : path, optional
        Default: ``checkpoints/`` in the directory that holds every seed's directory.

    Raises
    ------
    TrainingError
        An unknown algorithm, a bad step count, or a directory holding a different training.
    """
    algo = check_algo(spec.algo)
    if algo not in ACTION_MODES or spec.timesteps < 1 or not spec.seeds or set(out_dirs) != set(spec.seeds):
        raise TrainingError(f"cannot train {algo} with the JAX backend for seeds {list(spec.seeds)}")
    if spec.chunk_steps is not None and spec.chunk_steps < 1:
        raise TrainingError(f"chunk_steps must be at least 1, got {spec.chunk_steps}")
    task = get_task(spec.task)
    if not has_jax_env(task):
        raise TrainingError(no_jax_env(spec.task))
    cfg = spec.config
    data_dir = task.data_dir(spec.data_dir, cfg)
    table = task.load_data(data_dir)
    dataset = task.provenance(table)
    identities = {s: _identity(spec, s, dataset) for s in spec.seeds}
    if all(_finished(Path(out_dirs[s]), identities[s], overwrite) for s in spec.seeds):
        paths = tuple(Path(out_dirs[s]) / JAX_MODEL_FILE for s in spec.seeds)
        return JaxTrainOutcome(algo, tuple(spec.seeds), int(spec.timesteps), 0.0, 0.0, paths, already_complete=True)
    started_at = datetime.now(UTC).isoformat(timespec="seconds")
    settings = rejax_config(algo, cfg, spec.timesteps)
    checkpoint = Path(checkpoint_dir or Path(os.path.commonpath([Path(d) for d in out_dirs.values()])) / CHECKPOINT_DIR)
    checkpoint = checkpoint / CHECKPOINT_FILE
    if overwrite:
        checkpoint.unlink(missing_ok=True)
    for seed in spec.seeds:
        directory = Path(out_dirs[seed])
        for name in (JAX_MODEL_FILE, TRAIN_METADATA_FILE):
            (directory / name).unlink(missing_ok=True)
        record = {
            "identity": identities[seed],
            "rejax": settings,
            "data_dir": None if data_dir is None else str(Path(data_dir).resolve()),
        }
        write_train_config(directory, record)
    # The env's config carries the setting's reward switch; the algorithm reads only its training section.
    env_config = cfg.with_updates(no_physics_penalty=spec.no_physics_penalty)
    env = make_jax_env(task, env_config, table, action_mode=ACTION_MODES[algo])
    training = ChunkedTraining(algo, tuple(spec.seeds), spec.timesteps, env, cfg, spec.chunk_steps)
    sha256 = config_sha256({"seeds": list(spec.seeds), "identities": [identities[s] for s in spec.seeds]})
    run = run_chunks(training, checkpoint, sha256, on_progress=on_progress, on_note=on_note)
    states, plan = run.states, training.plan
    steps_now = plan.total_steps - (run.resumed_from or 0)
    paths = []
    for i, seed in enumerate(spec.seeds):
        directory = Path(out_dirs[seed])
        paths.append(save_network(directory / JAX_MODEL_FILE, algo, states, i))
        steps_done = int(np.max(states.global_step))  # one counter for all seeds (rejax's layout)
        atomic_write_json(
            directory / TRAIN_METADATA_FILE,
            {
                "complete": True,
                "backend": "jax",
                "algo": algo,
                "seed": int(seed),
                "seeds_in_batch": [int(s) for s in spec.seeds],
                "timesteps_requested": int(spec.timesteps),
                "timesteps_done": steps_done,
                "compile_s": round(run.compile_s, 3),
                "train_s": round(run.train_s, 3),
                "wall_s": round(run.compile_s + run.train_s, 3),
                "steps_per_s": round(steps_now / max(run.train_s, 1e-9), 2),
                "chunk_steps": plan.chunk_steps,
                "chunks_run": run.chunks_run,
                "checkpoint_s": round(run.checkpoint_s, 3),
                "resumed_from": run.resumed_from,
                "jax_devices": [str(d) for d in jax.devices()],
                "started_at": started_at,
                "command": redact_command(command if command is not None else sys.argv),
                "git_commit": git_commit(),
                "package_versions": package_versions(),
            },
        )
    checkpoint.unlink(missing_ok=True)  # the models are written: nothing to resume any more
    with contextlib.suppress(OSError):
        checkpoint.parent.rmdir()  # only if empty
    return JaxTrainOutcome(
        algo, tuple(spec.seeds), int(spec.timesteps), run.compile_s, run.train_s, tuple(paths),
        resumed_from=run.resumed_from, steps_trained=steps_now, states=states,
    )  # fmt: skip
