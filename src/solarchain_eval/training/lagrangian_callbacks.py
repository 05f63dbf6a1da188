"""The SB3 side of PPO-Lagrangian: the penalised-reward wrapper and the dual-ascent callback.

Imported only when ``ppo-lag`` is trained (it imports Stable-Baselines3). See
:mod:`solarchain_eval.training.lagrangian` for the algorithm.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from ..common.atomic_files import atomic_write_csv
from .lagrangian import LagrangianSettings, dual_update, log_frame

#: ``info`` key carrying the env's own reward (before the Lagrangian penalty) for the episode log.
UNPENALISED_REWARD_KEY = "reward_unpenalised"


class Multiplier:
    """λ, shared by the reward wrapper (reads it) and the callback (updates it)."""

    def __init__(self, value: float) -> None:
        self.value = float(value)


class PenalisedReward(VecEnvWrapper):
    """Return ``r - λ c`` (c = ``info["cost"]``) and keep r in ``info["reward_unpenalised"]``."""

    def __init__(self, venv: VecEnv, multiplier: Multiplier) -> None:
        super().__init__(venv)
        self.multiplier = multiplier

    def reset(self) -> Any:
        return self.venv.reset()

    def step_wait(self) -> Any:
        obs, rewards, dones, infos = self.venv.step_wait()
        costs = np.array([info["cost"] for info in infos], dtype=np.float64)
        for info, reward in zip(infos, rewards, strict=True):
            info[UNPENALISED_REWARD_KEY] = float(reward)
        penalised = (rewards.astype(np.float64) - self.multiplier.value * costs).astype(rewards.dtype)
        return obs, penalised, dones, infos


class LagrangianCallback(BaseCallback):
    """Sums each training episode's cost and takes the dual step at every rollout end.

    Each rollout's row (see :data:`~solarchain_eval.training.lagrangian.LAGRANGIAN_LOG_COLUMNS`) is
    appended to the log, written atomically to ``log_path`` right away (a resumed run reads it
    back), and recorded as ``lagrangian/*`` scalars in SB3's logger (TensorBoard when enabled).
    """

    def __init__(
        self,
        settings: LagrangianSettings,
        multiplier: Multiplier,
        log_path: Path,
        rows: list[dict[str, Any]] | None = None,
    ) -> None:
        super().__init__(verbose=0)
        self.settings = settings
        self.multiplier = multiplier
        self.log_path = Path(log_path)
        self.rows: list[dict[str, Any]] = list(rows or [])
        self._running: np.ndarray | None = None
        self._finished: list[float] = []

    def _on_training_start(self) -> None:
        self._running = np.zeros(self.training_env.num_envs)

    def _on_step(self) -> bool:
        assert self._running is not None
        for i, (info, done) in enumerate(zip(self.locals["infos"], self.locals["dones"], strict=True)):
            self._running[i] += info["cost"]
            if done:
                self._finished.append(float(self._running[i]))
                self._running[i] = 0.0
        return True

    def _on_rollout_end(self) -> None:
        s = self.settings
        cost = float(np.mean(self._finished)) if self._finished else float("nan")
        before = self.multiplier.value
        after = dual_update(before, cost, s.cost_limit, s.multiplier_lr)
        row = {
            "rollout": len(self.rows),
            "end_timestep": int(self.model.num_timesteps),
            "episodes": len(self._finished),
            "episode_cost": cost,
            "cost_limit": s.cost_limit,
            "violation": cost - s.cost_limit,
            "multiplier": before,
            "next_multiplier": after,
        }
        self.rows.append(row)
        self.multiplier.value = after
        self._finished = []
        atomic_write_csv(self.log_path, log_frame(self.rows))
        for key in ("multiplier", "episode_cost", "violation"):
            self.logger.record(f"lagrangian/{key}", row[key])
