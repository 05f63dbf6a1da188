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

from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..agents.checkpoints import (
    MODEL_FILE,
    TRAIN_CONFIG_FILE,
    TrainingError,
    check_algo,
    read_training_json,
)
from ..common.atomic_files import atomic_write_json
from ..tasks.registry import DEFAULT_TASK, get_task
from .lagrangian import LAGRANGIAN_ALGO, LAGRANGIAN_LOG_FILE

# The spec and the training session live in sb3_spec and sb3_session; the `x as x` imports keep
# their names importable from here.
from .sb3_session import TrainingSession, remove_tree, set_torch_threads
from .sb3_session import quiet_logger as quiet_logger
from .sb3_spec import CHECKPOINT_DIR, TRAIN_LOG_FILE, TRAIN_METADATA_FILE, TrainOutcome, TrainSpec, hyperparameters
from .sb3_spec import DEFAULT_CHECKPOINT_EVERY as DEFAULT_CHECKPOINT_EVERY
from .sb3_spec import dqn_learning_starts as dqn_learning_starts


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
    session = TrainingSession.start(spec, cfg, table, out_dir, identity, metadata)
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
            remove_tree(out_dir / CHECKPOINT_DIR)  # left over if a kill came right after the metadata
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


def _clear_training_dir(out_dir: Path) -> None:
    for name in (MODEL_FILE, TRAIN_LOG_FILE, TRAIN_METADATA_FILE, TRAIN_CONFIG_FILE, LAGRANGIAN_LOG_FILE):
        (out_dir / name).unlink(missing_ok=True)
    remove_tree(out_dir / CHECKPOINT_DIR)
