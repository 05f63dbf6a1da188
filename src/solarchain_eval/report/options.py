"""Options shared by the report's tables, figures and page."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .statistics import DEFAULT_CONFIDENCE, DEFAULT_RESAMPLES, DEFAULT_SEED

#: Units the bootstrap may resample: start days (the default, the coarsest) or episode seeds.
CLUSTER_UNITS = ("start_hour", "episode_seed")


@dataclass(frozen=True)
class ReportOptions:
    """How the report resamples and selects.

    Attributes
    ----------
    n_resamples
        Bootstrap resamples per interval.
    confidence
        Two-sided confidence level of every interval (0.95 = 95 %).
    seed
        Seed of every resampling stream and of the jitter of plotted points (deterministic output).
    cluster_by
        Column whose distinct values are the independent units the bootstrap resamples:
        ``start_hour`` (the episode's start day) or ``episode_seed``.
    case_policy, case_setting
        Where the case study's audit trace is looked for first (the paper's: PPO, no-physics LLM).
    """

    n_resamples: int = DEFAULT_RESAMPLES
    confidence: float = DEFAULT_CONFIDENCE
    seed: int = DEFAULT_SEED
    cluster_by: Literal["start_hour", "episode_seed"] = "start_hour"
    case_policy: str = "ppo"
    case_setting: str = "llm_no_physics"

    def bootstrap(self) -> dict:
        """Keyword arguments of the ``bootstrap_*`` functions."""
        return {"n_resamples": self.n_resamples, "confidence": self.confidence, "seed": self.seed}
