"""A model being trained (:class:`TrainingSession`): new or restored from its latest checkpoint,
trained with the progress monitor and checkpoints, then written out; and the SB3 set-up it needs
(vector env, torch threads, a quiet logger, the ppo-lag wrapper).

Stable-Baselines3 and torch are imported only inside these functions.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..agents.checkpoints import MODEL_FILE, algorithm_class, check_algo
from ..common.atomic_files import atomic_write_csv, atomic_write_json, atomic_write_with
from ..common.redaction import redact_command
from ..common.versions import git_commit, package_versions
from ..config import BenchmarkConfig
from ..evaluation.settings import setting_name
from ..tasks.base import training_log_fields
from ..tasks.registry import DEFAULT_TASK, get_task
from .lagrangian import LAGRANGIAN_ALGO, LAGRANGIAN_LOG_FILE
from .sb3_spec import CHECKPOINT_DIR, TRAIN_LOG_FILE, TRAIN_METADATA_FILE, TrainOutcome, TrainSpec


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


def make_vec_env(cfg: BenchmarkConfig, table: Any, n_envs: int, task: str = DEFAULT_TASK) -> Any:
    """SB3's vector env of ``n_envs`` of ``task``'s single envs on ``table``, each in a ``Monitor``."""
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    # SB3 steps its own vector env; each sub-env is the task's single env (as in evaluation).
    market = get_task(task)
    return DummyVecEnv([lambda: Monitor(market.make_env(cfg, table, action_mode=cfg.action_mode))] * n_envs)


def _resume_seed(seed: int, steps: int) -> int:
    # A resumed run must not replay the random streams of its first session: derive fresh ones.
    return int(np.random.SeedSequence([seed, steps]).generate_state(1)[0])


@dataclass
class TrainingSession:
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
        env = make_vec_env(cfg, table, cfg.training.n_envs, spec.task)
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
        remove_tree(out_dir / CHECKPOINT_DIR)
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


def remove_tree(path: Path) -> None:
    """Remove the folder ``path`` and all it holds, if it is there."""
    import shutil

    shutil.rmtree(path, ignore_errors=True)
