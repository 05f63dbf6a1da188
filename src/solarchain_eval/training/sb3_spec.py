"""What one Stable-Baselines3 training run is (:class:`TrainSpec`), the hyperparameters it gives
the SB3 constructor, what it yields (:class:`TrainOutcome`) and the files of a training directory.

:func:`~.sb3_trainer.train` runs a spec; :mod:`.sb3_session` holds the model while it trains.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..agents.checkpoints import TRAINABLE_ACTION_MODES, check_algo
from ..config import BenchmarkConfig
from ..tasks.registry import DEFAULT_TASK
from .lagrangian import LagrangianSettings

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
