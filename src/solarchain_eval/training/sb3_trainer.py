"""Train PPO, SAC or DQN (Stable-Baselines3) on SolarChain-Eval, resumably.

The paper's settings: ``MlpPolicy``, learning rate 3e-4, batch size 64, gamma 0.98 (the config's
``training`` section) and SB3's defaults for everything else; PPO and SAC act on the continuous
``Box(0, 1, (3,))`` env, DQN on the 125-point discrete grid with
``learning_starts = min(100, max(1, timesteps // 10))``. Models run on the CPU with one torch
thread by default (small MLPs gain nothing from more threads or a GPU, and parallel runs must
not oversubscribe the cores).

A training directory holds::

    model.zip             the trained model (plain ``PPO.load`` / ``SAC.load`` / ``DQN.load``)
    train_config.json     the resolved configuration and hyperparameters (written first)
    training_log.csv      one row per training episode (return, volume, violation, art. liquidity)
    train_metadata.json   wall time, steps/s, versions, resumes ("complete": true; written last)
    checkpoints/          the latest checkpoint while training runs (removed when it finishes)

Stable-Baselines3 and torch are imported only when a model is trained or loaded.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..agents.checkpoints import (
    MODEL_FILE,
    TRAIN_CONFIG_FILE,
    TRAINABLE_ACTION_MODES,
    TrainingError,
    algorithm_class,
    check_algo,
    read_training_json,
)
from ..common.atomic_files import atomic_write_csv, atomic_write_json, atomic_write_with
from ..common.redaction import redact_command
from ..common.versions import git_commit, package_versions
from ..config import BenchmarkConfig
from ..evaluation.settings import setting_name
from ..tasks.base import training_log_fields
from ..tasks.registry import DEFAULT_TASK, get_task
from .lagrangian import LAGRANGIAN_ALGO, LAGRANGIAN_LOG_FILE, LagrangianSettings

TRAIN_LOG_FILE = "training_log.csv"
TRAIN_METADATA_FILE = "train_metadata.json"
CHECKPOINT_DIR = "checkpoints"
DEFAULT_CHECKPOINT_EVERY = 25_000


def dqn_learning_starts(timesteps: int) -> int:
    """The original release's DQN warm-up: ``min(100, max(1, timesteps // 10))`` steps."""
    return min(100, max(1, timesteps // 10))


def hyperparameters(algo: str, config: BenchmarkConfig, timesteps: int) -> dict[str, Any]:
    """Keyword arguments given to the SB3 constructor on top of its defaults."""
    t = config.training
    params: dict[str, Any] = {"learning_rate": t.learning_rate, "batch_size": t.batch_size, "gamma": t.gamma}
    if check_algo(algo) == "dqn":
        params["learning_starts"] = dqn_learning_starts(timesteps)
    return params


def quiet_logger() -> Any:
    """An SB3 logger with no outputs.

    Without one, SB3's default logger set-up creates an empty ``/tmp/SB3-<time>`` directory on
    every ``learn()`` (where no TensorBoard folder is given).
    """
    from stable_baselines3.common.logger import Logger

    return Logger(folder=None, output_formats=[])


def set_torch_threads(threads: int) -> None:
    """Limit torch (and the BLAS libraries it loads later) to ``threads`` threads."""
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(name, str(threads))
    import torch

    torch.set_num_threads(threads)


@dataclass(frozen=True)
class TrainSpec:
    """One training run.

    Parameters
    ----------
    algo : {"ppo", "sac", "dqn", "ppo-lag"}
    seed : int
        Seeds SB3 (torch, numpy, the action space) and the training env's first reset.
    timesteps : int
        Environment steps to train for (PPO rounds up to whole 2,048-step rollouts).
    no_physics_penalty : bool
        Train on the ablation reward (no λp (V + A) term).
    data_dir : path, optional
        Dataset directory (default: the config's, else the embedded default dataset).
    config : BenchmarkConfig
    checkpoint_every : int
        Timesteps between checkpoints; 0 disables them.
    tensorboard_dir : path, optional
        Write SB3's scalars plus per-episode return, physics violation and artificial liquidity.
    torch_threads : int
    device : str
        Torch device for the networks ("cpu" unless you know a GPU helps these small MLPs).
    lagrangian : LagrangianSettings, optional
        The cost limit and dual ascent of "ppo-lag" (required there, ignored otherwise).
    task : str
        The task to train on (:func:`~solarchain_eval.tasks.registry.get_task`; default the solar market).
    """

    algo: str
    seed: int
    timesteps: int
    no_physics_penalty: bool = False
    data_dir: Path | None = None
    config: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    checkpoint_every: int = DEFAULT_CHECKPOINT_EVERY
    tensorboard_dir: Path | None = None
    torch_threads: int = 1
    device: str = "cpu"
    lagrangian: LagrangianSettings | None = None  # required by (and only used for) "ppo-lag"
    task: str = DEFAULT_TASK

    def resolved_config(self) -> BenchmarkConfig:
        cfg = self.config.with_updates(
            action_mode=TRAINABLE_ACTION_MODES[check_algo(self.algo)], no_physics_penalty=self.no_physics_penalty
        )
        payload = cfg.model_dump()
        payload["training"]["timesteps"] = int(self.timesteps)
        return BenchmarkConfig.model_validate(payload)


@dataclass
class TrainOutcome:
    out_dir: Path
    model_path: Path
    timesteps_done: int
    wall_s: float
    steps_per_s: float
    resumed_from: list[int]
    steps_before: int = 0
    already_complete: bool = False


def _identity(spec: TrainSpec, dataset: dict[str, Any]) -> dict[str, Any]:
    """Everything that decides the trained model; a resume must match it exactly."""
    cfg = spec.resolved_config()
    extra = {"lagrangian": spec.lagrangian.describe()} if spec.algo == LAGRANGIAN_ALGO and spec.lagrangian else {}
    # Only another task is named, so that the identity (and resumes) of solar trainings is unchanged.
    named = {"task": spec.task} if spec.task != DEFAULT_TASK else {}
    return {
        **named,
        **extra,
        "algo": check_algo(spec.algo),
        "seed": int(spec.seed),
        "timesteps": int(spec.timesteps),
        "no_physics_penalty": bool(spec.no_physics_penalty),
        "action_mode": cfg.action_mode,
        "policy": "MlpPolicy",
        "hyperparameters": hyperparameters(spec.algo, cfg, spec.timesteps),
        "device": spec.device,
        "dataset_sha256": dataset.get("files", {}),
        "config": cfg.model_dump(mode="json"),
    }


def differences(old: dict[str, Any], new: dict[str, Any], prefix: str = "") -> list[str]:
    """Human-readable ``key: old -> new`` lines for nested dicts (used in resume errors)."""
    diffs = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            diffs.extend(differences(a, b, f"{prefix}{key}."))
        elif a != b:
            diffs.append(f"{prefix}{key}: {a!r} -> {b!r}")
    return diffs


def _make_vec_env(cfg: BenchmarkConfig, table: Any, n_envs: int, task: str = DEFAULT_TASK) -> Any:
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    # SB3 steps its own vector env; each sub-env is the task's single env (as in evaluation).
    market = get_task(task)
    return DummyVecEnv([lambda: Monitor(market.make_env(cfg, table, action_mode=cfg.action_mode))] * n_envs)


def _resume_seed(seed: int, steps: int) -> int:
    # A resumed run must not replay the random streams of its first session: derive fresh ones.
    return int(np.random.SeedSequence([seed, steps]).generate_state(1)[0])


def train(
    spec: TrainSpec,
    out_dir: Path,
    *,
    on_progress: Callable[[int], None] | None = None,
    overwrite: bool = False,
    command: list[str] | None = None,
) -> TrainOutcome:
    """Train one model into ``out_dir``, resuming from its last checkpoint if there is one.

    Parameters
    ----------
    spec : TrainSpec
    out_dir : path
        The training directory (see the module docstring).
    on_progress : callable, optional
        Called with the timesteps done so far.
    overwrite : bool
        Discard a finished or differently configured training in ``out_dir`` instead of failing.
    command : list of str, optional
        The command line recorded in the metadata.

    Returns
    -------
    TrainOutcome
        ``already_complete`` is true when ``out_dir`` held this exact finished training.

    Raises
    ------
    TrainingError
        ``out_dir`` holds a different training (the message lists what differs), or
        TensorBoard logging was asked for without the tensorboard package.
    """
    algo = check_algo(spec.algo)
    if spec.timesteps < 1:
        raise TrainingError(f"timesteps must be at least 1, got {spec.timesteps}")
    if algo == LAGRANGIAN_ALGO and spec.lagrangian is None:
        raise TrainingError.about("ppo-lag needs a cost limit: pass {opt_lagrangian} (the limit D on the episode cost)")
    cfg = spec.resolved_config()
    task = get_task(spec.task)
    data_dir = task.data_dir(spec.data_dir, cfg)
    table = task.load_data(data_dir)
    dataset = task.provenance(table)
    identity = _identity(spec, dataset)
    out_dir = Path(out_dir)
    finished, metadata = _previous_training(out_dir, identity, overwrite)
    if finished is not None:
        return finished
    if spec.tensorboard_dir is not None:
        import importlib.util

        if importlib.util.find_spec("tensorboard") is None:
            raise TrainingError.about(
                "{opt_tensorboard_dir} needs the tensorboard package: pip install -e '.[tensorboard]' in a clone of the repository"
            )

    set_torch_threads(spec.torch_threads)
    started_at = datetime.now(UTC).isoformat(timespec="seconds")
    atomic_write_json(
        out_dir / TRAIN_CONFIG_FILE,
        {
            "identity": identity,
            "data_dir": None if data_dir is None else str(Path(data_dir).resolve()),  # None: a task without a dataset
            "dataset": dataset,
            "written_at": started_at,
        },
    )
    session = _TrainingSession.start(spec, cfg, table, out_dir, identity, metadata)
    learn_s = session.learn(spec, algo, on_progress)
    return session.finish(spec, algo, learn_s, started_at, command)


def _previous_training(
    out_dir: Path, identity: dict[str, Any], overwrite: bool
) -> tuple[TrainOutcome | None, dict[str, Any] | None]:
    """What ``out_dir`` already holds: the outcome of this exact finished training (else None) and
    the metadata of an interrupted one to resume. A different training is an error unless ``overwrite``."""
    config_path, metadata_path = out_dir / TRAIN_CONFIG_FILE, out_dir / TRAIN_METADATA_FILE
    previous = read_training_json(config_path)
    if previous is not None and previous.get("identity") != identity:
        if not overwrite:
            diffs = differences(previous.get("identity") or {}, identity)
            raise TrainingError.about(
                "{out_dir} holds a different training ({diffs}); choose another output directory or pass {opt_overwrite}",
                out_dir=out_dir,
                diffs="; ".join(diffs[:6]),
            )
        _clear_training_dir(out_dir)
        previous = None
    metadata = read_training_json(metadata_path)
    if previous is not None and metadata and metadata.get("complete") and (out_dir / MODEL_FILE).is_file():
        if not overwrite:
            _remove_tree(out_dir / CHECKPOINT_DIR)  # left over if a kill came right after the metadata
            outcome = TrainOutcome(
                out_dir,
                out_dir / MODEL_FILE,
                int(metadata["timesteps_done"]),
                float(metadata["wall_s"]),
                float(metadata["steps_per_s"]),
                list(metadata.get("resumed_from", [])),
                already_complete=True,
            )
            return outcome, metadata
        _clear_training_dir(out_dir)
    return None, metadata


@dataclass
class _TrainingSession:
    """A model being trained into ``out_dir``: new, or restored from its latest checkpoint."""

    out_dir: Path
    model: Any
    env: Any
    store: Any
    log: Any
    checkpoint: Any
    wall_before: float
    resumed_from: list[int]
    steps_before: int = 0
    callbacks: list[Any] = field(default_factory=list)  # besides the monitor (ppo-lag: the dual ascent)

    @classmethod
    def start(cls, spec: TrainSpec, cfg: BenchmarkConfig, table: Any, out_dir: Path, identity: dict, metadata):
        from .callbacks import CheckpointStore, EpisodeLog, load_replay_buffer

        algo_cls = algorithm_class(spec.algo)
        env = _make_vec_env(cfg, table, cfg.training.n_envs, spec.task)
        fields = training_log_fields(get_task(spec.task))
        store = CheckpointStore(out_dir / CHECKPOINT_DIR)
        checkpoint = store.latest()
        callbacks: list[Any] = []
        if check_algo(spec.algo) == LAGRANGIAN_ALGO:
            env, dual = _lagrangian(spec, env, out_dir, checkpoint.steps if checkpoint else 0)
            callbacks.append(dual)
        tb_dir = str(spec.tensorboard_dir) if spec.tensorboard_dir is not None else None
        resumed_from = list((metadata or {}).get("resumed_from", []))
        if checkpoint is None:
            model = algo_cls(
                "MlpPolicy",
                env,
                seed=spec.seed,
                verbose=0,
                tensorboard_log=tb_dir,
                device=spec.device,
                **identity["hyperparameters"],
            )
            log, wall_before = EpisodeLog(env.num_envs, fields=fields), 0.0
        else:
            model = algo_cls.load(checkpoint.model, env=env, device=spec.device, tensorboard_log=tb_dir)
            if checkpoint.replay_buffer is not None:
                load_replay_buffer(model.replay_buffer, checkpoint.replay_buffer)
            model.set_random_seed(_resume_seed(spec.seed, checkpoint.steps))
            wall_before = checkpoint.wall_s
            rows = EpisodeLog.read(checkpoint.log, fields)
            log = EpisodeLog(env.num_envs, rows, wall_offset_s=wall_before, fields=fields)
            resumed_from.append(checkpoint.steps)
            # Record the resume now: a run killed again must still say it was resumed.
            atomic_write_json(out_dir / TRAIN_METADATA_FILE, {"complete": False, "resumed_from": resumed_from})
        if tb_dir is None:
            model.set_logger(quiet_logger())
        return cls(out_dir, model, env, store, log, checkpoint, wall_before, resumed_from, callbacks=callbacks)

    def learn(self, spec: TrainSpec, algo: str, on_progress: Callable[[int], None] | None) -> float:
        """Train up to ``spec.timesteps``; the seconds it took."""
        from .callbacks import TrainingMonitor

        self.steps_before = int(self.model.num_timesteps)
        monitor = TrainingMonitor(
            self.log,
            on_progress=on_progress,
            checkpoints=self.store,
            checkpoint_every=spec.checkpoint_every,
            wall_offset_s=self.wall_before,
        )
        learn_started = time.perf_counter()
        self.model.learn(
            total_timesteps=max(spec.timesteps - self.steps_before, 0),
            callback=[monitor, *self.callbacks] if self.callbacks else monitor,
            reset_num_timesteps=self.checkpoint is None,
            tb_log_name=f"{algo}-{setting_name(agentic=False, no_physics_penalty=spec.no_physics_penalty)}-{spec.seed}",
        )
        learn_s = time.perf_counter() - learn_started
        self.env.close()
        return learn_s

    def finish(
        self, spec: TrainSpec, algo: str, learn_s: float, started_at: str, command: list[str] | None
    ) -> TrainOutcome:
        """Write the model, the training log and the metadata (last); drop the checkpoints."""
        out_dir, model, log = self.out_dir, self.model, self.log
        model_path = atomic_write_with(out_dir / MODEL_FILE, lambda tmp: model.save(tmp))
        atomic_write_csv(out_dir / TRAIN_LOG_FILE, log.frame())
        steps_done = int(model.num_timesteps)
        wall_s = self.wall_before + learn_s
        steps_per_s = (steps_done - self.steps_before) / learn_s if learn_s > 0 else 0.0
        atomic_write_json(
            out_dir / TRAIN_METADATA_FILE,
            {
                "complete": True,
                "algo": algo,
                "seed": int(spec.seed),
                "timesteps_requested": int(spec.timesteps),
                "timesteps_done": steps_done,
                "episodes": len(log.rows),
                "wall_s": round(wall_s, 3),
                "steps_per_s": round(steps_per_s, 2),
                "torch_threads": spec.torch_threads,
                "resumed_from": self.resumed_from,
                "started_at": started_at,
                "command": redact_command(command if command is not None else sys.argv),
                "git_commit": git_commit(),
                "package_versions": package_versions(),
            },
        )
        _remove_tree(out_dir / CHECKPOINT_DIR)
        return TrainOutcome(out_dir, model_path, steps_done, wall_s, steps_per_s, self.resumed_from)


def _lagrangian(spec: TrainSpec, env: Any, out_dir: Path, resumed_at: int) -> tuple[Any, Any]:
    """``env`` wrapped in the penalised reward, and the dual-ascent callback (λ and its log
    restored from ``lagrangian_log.csv`` when resuming at step ``resumed_at``)."""
    from .lagrangian import resume_multiplier
    from .lagrangian_callbacks import LagrangianCallback, Multiplier, PenalisedReward

    assert spec.lagrangian is not None
    value, rows = resume_multiplier(out_dir / LAGRANGIAN_LOG_FILE, spec.lagrangian, resumed_at)
    multiplier = Multiplier(value)
    callback = LagrangianCallback(spec.lagrangian, multiplier, out_dir / LAGRANGIAN_LOG_FILE, rows)
    return PenalisedReward(env, multiplier), callback


def _remove_tree(path: Path) -> None:
    import shutil

    shutil.rmtree(path, ignore_errors=True)


def _clear_training_dir(out_dir: Path) -> None:
    for name in (MODEL_FILE, TRAIN_LOG_FILE, TRAIN_METADATA_FILE, TRAIN_CONFIG_FILE, LAGRANGIAN_LOG_FILE):
        (out_dir / name).unlink(missing_ok=True)
    _remove_tree(out_dir / CHECKPOINT_DIR)
