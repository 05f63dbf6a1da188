"""PPO-Lagrangian: PPO on the penalised reward r - λ c with λ set by dual ascent (docs/training.md#ppo-lagrangian).

The constrained problem is ``max E[Σ r]`` subject to ``J_c = E[Σ c] <= D``, with c the env's
``info["cost"]`` (V + A, the physics cost) and D the per-episode cost limit. Its Lagrangian
relaxation is optimised by alternating:

1. **Primal step.** Rollout k (SB3 PPO's ``n_steps`` per env) is collected with the multiplier
   λ_k fixed: every stored reward is ``r_t - λ_k c_t``. PPO's advantages, returns and update
   use those penalised rewards unchanged (one value network learns the penalised return).
2. **Dual step.** After the rollout, J_c,k is the mean cost of the training episodes that ended
   in it, and ``λ_{k+1} = max(0, λ_k + lr_λ (J_c,k - D))``; rollout k + 1 uses λ_{k+1}.

This module holds the settings, the dual update and the log's columns (no SB3 import);
:mod:`solarchain_eval.training.lagrangian_callbacks` holds the SB3 reward wrapper and callback.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from ..agents.checkpoints import TrainingError

LAGRANGIAN_ALGO = "ppo-lag"
LAGRANGIAN_LOG_FILE = "lagrangian_log.csv"
#: One row per rollout: what the multiplier was, the episode cost it saw, and the update.
LAGRANGIAN_LOG_COLUMNS = (
    "rollout",
    "end_timestep",
    "episodes",
    "episode_cost",
    "cost_limit",
    "violation",
    "multiplier",
    "next_multiplier",
)
DEFAULT_MULTIPLIER_LR = 0.1
#: The grid's default D: on the published month a static policy's episode cost is about 11.4 to
#: 11.9, the least backing the action ranges allow about 10 to 10.3 (docs/training.md#ppo-lagrangian).
DEFAULT_COST_LIMIT = 10.5


@dataclass(frozen=True)
class LagrangianSettings:
    """The constraint and the dual ascent of PPO-Lagrangian.

    Parameters
    ----------
    cost_limit : float
        D, the limit on the expected episode cost Σ c (c = V + A per step).
    multiplier_lr : float
        lr_λ, the dual ascent step size per rollout.
    initial_multiplier : float
        λ_0.
    """

    cost_limit: float
    multiplier_lr: float = DEFAULT_MULTIPLIER_LR
    initial_multiplier: float = 0.0

    def __post_init__(self) -> None:
        for name in ("cost_limit", "multiplier_lr", "initial_multiplier"):
            value = getattr(self, name)
            if not math.isfinite(value) or value < 0:
                # {opt_<name>}: the field here, the flag (--cost-limit, ...) on the command line
                raise TrainingError.about(
                    f"PPO-Lagrangian {{opt_{name}}} must be finite and >= 0, got {{value}}", value=value
                )

    def describe(self) -> dict[str, float]:
        return {
            "cost_limit": float(self.cost_limit),
            "multiplier_lr": float(self.multiplier_lr),
            "initial_multiplier": float(self.initial_multiplier),
        }


def dual_update(multiplier: float, episode_cost: float, cost_limit: float, lr: float) -> float:
    """One dual-ascent step: ``max(0, λ + lr (J_c - D))``; a rollout without a finished episode
    (``episode_cost`` NaN) leaves λ unchanged."""
    if math.isnan(episode_cost):
        return float(multiplier)
    return max(0.0, float(multiplier) + float(lr) * (float(episode_cost) - float(cost_limit)))


def resume_multiplier(path: Path, settings: LagrangianSettings, steps: int) -> tuple[float, list[dict[str, Any]]]:
    """λ and the log rows of a run resumed at ``steps`` (rows of later rollouts are dropped).

    A checkpoint is taken at a rollout start, after the dual step of every rollout that ended
    at or before it, so the last kept row's ``next_multiplier`` is the λ to continue with.
    """
    if steps <= 0 or not Path(path).is_file():
        return settings.initial_multiplier, []
    frame = pd.read_csv(path)
    missing = [c for c in LAGRANGIAN_LOG_COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(f"{path}: the Lagrangian log lacks column(s) {', '.join(missing)}")
    rows = frame[frame["end_timestep"] <= steps].to_dict("records")
    return (float(rows[-1]["next_multiplier"]) if rows else settings.initial_multiplier), rows


def log_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=list(LAGRANGIAN_LOG_COLUMNS))
