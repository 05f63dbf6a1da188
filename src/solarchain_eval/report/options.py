"""Options shared by the report's tables, figures and page, with their defaults and choices.

Light on purpose (no pandas, scipy or matplotlib): the ``report`` command's ``--help`` reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..common.errors import InputDataError, NamesOptions
from ..protocol import PAPER_SEED

#: Resamples per bootstrap interval (rliable's examples use 2,000).
DEFAULT_RESAMPLES = 2000
DEFAULT_CONFIDENCE = 0.95
DEFAULT_SEED = PAPER_SEED  # the bootstrap's seed
#: Units the bootstrap may resample: start days (the default, the coarsest) or episode seeds.
CLUSTER_UNITS = ("start_hour", "episode_seed")
#: Output formats of the tables (``md``, ``tex``, ``csv``) and the page (``html``).
FORMATS = ("md", "tex", "csv", "html")
#: What a run can be checked against (``report --against``): the paper's published values.
AGAINST_CHOICES = ("paper",)
#: Output formats of a leaderboard: ``leaderboard.csv``, ``leaderboard.md``, ``leaderboard.html``.
LEADERBOARD_FORMATS = ("csv", "md", "html")


class ReportDataError(NamesOptions, InputDataError, ValueError):
    """The run's files are missing, malformed or inconsistent (the message names file, column, row)."""


def parse_formats(text: str, choices: tuple[str, ...] = FORMATS, what: str = "report") -> tuple[str, ...]:
    """``"md,tex"`` -> ("md", "tex"); raises ValueError on a format not in ``choices`` (``what`` names them)."""
    formats = tuple(dict.fromkeys(part.strip().lower() for part in text.split(",") if part.strip()))
    unknown = [f for f in formats if f not in choices]
    if unknown or not formats:
        raise ValueError(f"unknown {what} format(s) {', '.join(unknown) or '(none)'}; choose from {', '.join(choices)}")
    return formats


#: Default limit on the bytes a tarball's files unpack to (raise it with ``--max-unpacked-mb``).
DEFAULT_MAX_UNPACKED_MB = 4096
#: Default limit on a tarball's members, files and folders (raise it with ``--max-members``).
DEFAULT_MAX_MEMBERS = 100_000


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


@dataclass(frozen=True)
class LeaderboardOptions:
    """How a leaderboard is built (``solarchain-eval leaderboard`` and :func:`~solarchain_eval.report.leaderboard.make_leaderboards`).

    Attributes
    ----------
    formats
        Files to write: ``csv``, ``md``, ``html`` (the Pareto figure comes with ``md`` or ``html``).
    split
        Write one board per protocol (``BOARD/<id>/``) instead of refusing inputs of different protocols.
    n_resamples, confidence, seed
        Start-day bootstrap resamples per interval, two-sided confidence level, resampling seed.
    max_unpacked_mb, max_members
        What a tarball input may unpack to, checked before anything is written (docs/security.md#tarballs).
    """

    formats: tuple[str, ...] = LEADERBOARD_FORMATS
    split: bool = False
    n_resamples: int = DEFAULT_RESAMPLES
    confidence: float = DEFAULT_CONFIDENCE
    seed: int = DEFAULT_SEED
    max_unpacked_mb: float = DEFAULT_MAX_UNPACKED_MB
    max_members: int = DEFAULT_MAX_MEMBERS

    def bootstrap(self) -> dict:
        """Keyword arguments of the ``bootstrap_*`` functions."""
        return {"n_resamples": self.n_resamples, "confidence": self.confidence, "seed": self.seed}
