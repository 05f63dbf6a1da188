"""What happens during an SB3 training run: episode log, progress, TensorBoard scalars, checkpoints.

Imported only by the training session (:mod:`solarchain_eval.training.sb3_session`, which imports Stable-Baselines3).

Checkpoints are taken when a rollout starts, i.e. right after the previous update: the saved
parameters, step counter and (SAC/DQN) replay buffer are then mutually consistent. Each
checkpoint is three files written atomically (``model-<steps>.zip``, ``replay_buffer-<steps>.npz``,
``training_log-<steps>.csv``) and then ``state.json`` naming them; only a checkpoint that
``state.json`` names is ever read, so a kill at any moment leaves a usable earlier checkpoint.

The replay buffer is stored as its filled rows only (SB3's own ``save_replay_buffer`` pickles
all 1,000,000 preallocated rows, about 110 MB, whatever the number of steps taken).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

from ..common.atomic_files import atomic_write_csv, atomic_write_json, atomic_write_with, read_csv_exact
from ..tasks.base import TrainLogField

#: ``training_log.csv``'s columns (one row per finished training episode) around the task's own
#: (:func:`~solarchain_eval.tasks.base.training_log_fields`; the solar market: volume, V, artificial
#: liquidity and cost).
LEADING_COLUMNS = ("episode", "end_timestep", "episode_return", "episode_length")
TRAILING_COLUMNS = ("wall_s",)
STATE_FILE = "state.json"
PROGRESS_EVERY_STEPS = 512  # how often the progress callback is told (a callback per step costs time)


def train_log_columns(fields: Sequence[TrainLogField] = ()) -> tuple[str, ...]:
    """The columns of a training log with the task's ``fields``."""
    return (*LEADING_COLUMNS, *(f.column for f in fields), *TRAILING_COLUMNS)


class EpisodeLog:
    """Per-episode return and length, and the sums (or means) of the task's ``info`` fields.

    Parameters
    ----------
    n_envs : int
    rows : list of dict, optional
        Rows logged before (a resumed training).
    wall_offset_s : float
    fields : sequence of TrainLogField
        The task's log columns (the solar market's: ``physics_violation_rate`` is the episode mean
        of the per-step V; ``artificial_liquidity_MWh`` and ``episode_volume`` are episode sums in
        MWh, as in the evaluation metrics).
    """

    def __init__(
        self,
        n_envs: int,
        rows: list[dict[str, float]] | None = None,
        wall_offset_s: float = 0.0,
        fields: Sequence[TrainLogField] = (),
    ) -> None:
        self.rows: list[dict[str, float]] = list(rows or [])
        self.fields = tuple(fields)
        self._width = len(self.fields) + 1  # the return, then each field
        self._acc = [[0.0] * self._width + [0] for _ in range(n_envs)]
        self._start = time.perf_counter() - wall_offset_s

    def add_step(
        self, env_index: int, info: dict[str, Any], reward: float, done: bool, timestep: int
    ) -> dict[str, float] | None:
        acc = self._acc[env_index]
        acc[0] += reward
        for i, field in enumerate(self.fields, start=1):
            acc[i] += info[field.info_key]
        acc[-1] += 1
        if not done:
            return None
        n = acc[-1]
        row = {"episode": len(self.rows), "end_timestep": timestep, "episode_return": acc[0], "episode_length": n}
        for i, field in enumerate(self.fields, start=1):
            row[field.column] = acc[i] / n if field.mean else acc[i]
        row["wall_s"] = round(time.perf_counter() - self._start, 3)
        self.rows.append(row)
        self._acc[env_index] = [0.0] * self._width + [0]
        return row

    def frame(self) -> pd.DataFrame:
        return pd.DataFrame(self.rows, columns=list(train_log_columns(self.fields)))

    @staticmethod
    def read(path: Path, fields: Sequence[TrainLogField] = ()) -> list[dict[str, float]]:
        frame = read_csv_exact(path)
        missing = [c for c in train_log_columns(fields) if c not in frame.columns]
        if missing:
            raise ValueError(f"{path}: training log lacks column(s) {', '.join(missing)}")
        return frame.to_dict("records")


def _buffer_arrays(buffer: ReplayBuffer) -> dict[str, np.ndarray]:
    return {
        name: value
        for name, value in vars(buffer).items()
        if isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == buffer.buffer_size
    }


def save_replay_buffer(buffer: ReplayBuffer, path: Path) -> None:
    """Write the filled rows of ``buffer`` (and its position) to an ``.npz`` file at ``path``."""
    rows = buffer.buffer_size if buffer.full else buffer.pos
    arrays = {name: value[:rows] for name, value in _buffer_arrays(buffer).items()}
    with open(path, "wb") as handle:  # a handle: np.savez would append ".npz" to a path
        np.savez(handle, _pos=np.int64(buffer.pos), _full=np.bool_(buffer.full), **arrays)


def load_replay_buffer(buffer: ReplayBuffer, path: Path) -> None:
    """Fill a freshly built ``buffer`` from :func:`save_replay_buffer`'s file."""
    targets = _buffer_arrays(buffer)
    with np.load(path) as saved:
        for name, target in targets.items():
            if name not in saved:
                raise ValueError(f"{path}: the replay buffer checkpoint lacks '{name}'")
            rows = saved[name]
            if rows.shape[1:] != target.shape[1:] or rows.shape[0] > target.shape[0]:
                raise ValueError(f"{path}: '{name}' has shape {rows.shape}, the buffer {target.shape}")
            target[: rows.shape[0]] = rows
        buffer.pos = int(saved["_pos"])
        buffer.full = bool(saved["_full"])


@dataclass(frozen=True)
class Checkpoint:
    steps: int
    model: Path
    replay_buffer: Path | None
    log: Path
    wall_s: float


class CheckpointStore:
    """The latest checkpoint of one training run, in ``directory``."""

    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)

    def latest(self) -> Checkpoint | None:
        state_path = self.directory / STATE_FILE
        if not state_path.is_file():
            return None
        state = json.loads(state_path.read_text(encoding="utf-8"))
        files = {key: self.directory / name if name else None for key, name in state["files"].items()}
        for path in files.values():
            if path is not None and not path.is_file():
                raise FileNotFoundError(f"checkpoint file {path} named in {state_path} is missing")
        return Checkpoint(
            int(state["steps"]), files["model"], files["replay_buffer"], files["log"], float(state["wall_s"])
        )

    def save(self, model: BaseAlgorithm, log: EpisodeLog, wall_s: float) -> Checkpoint:
        steps = int(model.num_timesteps)
        self.directory.mkdir(parents=True, exist_ok=True)
        model_path = atomic_write_with(self.directory / f"model-{steps}.zip", lambda tmp: model.save(tmp))
        buffer_path = None
        if isinstance(model, OffPolicyAlgorithm) and model.replay_buffer is not None:
            buffer = model.replay_buffer
            buffer_path = atomic_write_with(
                self.directory / f"replay_buffer-{steps}.npz", lambda tmp: save_replay_buffer(buffer, tmp)
            )
        log_path = atomic_write_csv(self.directory / f"training_log-{steps}.csv", log.frame())
        files = {
            "model": model_path.name,
            "replay_buffer": buffer_path.name if buffer_path else None,
            "log": log_path.name,
        }
        atomic_write_json(self.directory / STATE_FILE, {"steps": steps, "wall_s": round(wall_s, 3), "files": files})
        keep = {STATE_FILE, *[name for name in files.values() if name]}
        for path in self.directory.iterdir():  # older checkpoints and leftovers of a killed save
            if path.name not in keep:
                path.unlink(missing_ok=True)
        return Checkpoint(steps, model_path, buffer_path, log_path, wall_s)


class TrainingMonitor(BaseCallback):
    """SB3 callback: episode log, progress reports, TensorBoard episode scalars, checkpoints.

    Parameters
    ----------
    log : EpisodeLog
    on_progress : callable, optional
        Called with the number of timesteps done so far (every 512 steps and at the end).
    checkpoints : CheckpointStore, optional
    checkpoint_every : int
        Timesteps between checkpoints (0: none); a checkpoint waits for the next rollout start.
    wall_offset_s : float
        Training seconds spent before this session (resumed runs).
    """

    def __init__(
        self,
        log: EpisodeLog,
        *,
        on_progress: Callable[[int], None] | None = None,
        checkpoints: CheckpointStore | None = None,
        checkpoint_every: int = 0,
        wall_offset_s: float = 0.0,
    ) -> None:
        super().__init__(verbose=0)
        self.log = log
        self.on_progress = on_progress
        self.checkpoints = checkpoints
        self.checkpoint_every = checkpoint_every
        self.wall_offset_s = wall_offset_s
        self.checkpointed_at = 0
        self._writer: Any = None
        self._next_report = 0
        self._started = time.perf_counter()

    def wall_s(self) -> float:
        return self.wall_offset_s + time.perf_counter() - self._started

    def _on_training_start(self) -> None:
        from stable_baselines3.common.logger import TensorBoardOutputFormat

        for output in self.logger.output_formats:
            if isinstance(output, TensorBoardOutputFormat):
                self._writer = output.writer
        self.checkpointed_at = int(self.model.num_timesteps)
        self._next_report = self.model.num_timesteps + PROGRESS_EVERY_STEPS

    def _on_rollout_start(self) -> None:
        steps = int(self.model.num_timesteps)
        if (
            self.checkpoints is not None
            and self.checkpoint_every > 0
            and steps - self.checkpointed_at >= self.checkpoint_every
        ):
            self.checkpoints.save(self.model, self.log, self.wall_s())
            self.checkpointed_at = steps

    def _on_step(self) -> bool:
        infos = self.locals["infos"]
        dones = self.locals["dones"]
        rewards = self.locals["rewards"]
        steps = int(self.num_timesteps)
        for i, info in enumerate(infos):
            # PPO-Lagrangian trains on r - λ c; the log keeps the env's own reward r.
            reward = float(info.get("reward_unpenalised", rewards[i]))
            row = self.log.add_step(i, info, reward, bool(dones[i]), steps)
            if row is not None and self._writer is not None:
                for key in ("episode_return", *(f.column for f in self.log.fields)):
                    self._writer.add_scalar(f"episode/{key}", row[key], steps)
        if steps >= self._next_report and self.on_progress is not None:
            self.on_progress(steps)
            self._next_report = steps + PROGRESS_EVERY_STEPS
        return True

    def _on_training_end(self) -> None:
        if self._writer is not None:
            self._writer.flush()
        if self.on_progress is not None:
            self.on_progress(int(self.num_timesteps))
