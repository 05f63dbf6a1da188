"""What a chunked JAX training reports between its chunks (importable without JAX).

A JAX training runs as compiled chunks of env steps (:mod:`.jax_chunks`); after each chunk the
trainer hands a :class:`ChunkProgress` to its caller, which shows it (``train``: a progress
display on a terminal, plain lines otherwise; ``paper``: the same per train unit, and a line in
the unit's ``unit.log``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Env steps per model in one chunk, per algorithm: about 13 s per chunk for a grid seed group
#: (three seeds vmapped, one CPU core) at the measured rates of docs/performance.md#jax-training
#: (SAC 153, PPO 16,604, DQN 9,496 steps/s per model; about 13 % slower with a second group on
#: the other core), so that progress and checkpoints come well within 30 s on 2 CPU cores.
DEFAULT_CHUNK_STEPS = {"sac": 2_000, "ppo": 204_800, "dqn": 120_000}

#: Finished episodes per environment whose returns make the "recent return".
RECENT_EPISODES = 10


@dataclass(frozen=True)
class ChunkProgress:
    """One chunk of a JAX training done (and checkpointed).

    Attributes
    ----------
    algo : str
    seeds : tuple of int
    chunk, chunks : int
        Chunks done and in total (at this training's chunk size; chunk boundaries fall on
        multiples of the chunk size, counted from step 0 also after a resume).
    steps_done, total_steps : int
        Env steps per model.
    recent_return : float or None
        Mean return of the last :data:`RECENT_EPISODES` finished training episodes of every
        environment of every seed (None before the first episode ends).
    steps_per_s : float
        Env steps per model per second since this call started (compilation excluded, checkpoints
        included).
    eta_s : float or None
        Seconds to the end at ``steps_per_s``.
    resumed_from : int or None
        The step this call resumed from (None: it started from scratch).
    """

    algo: str
    seeds: tuple[int, ...]
    chunk: int
    chunks: int
    steps_done: int
    total_steps: int
    recent_return: float | None
    steps_per_s: float
    eta_s: float | None
    resumed_from: int | None = None

    @property
    def fraction(self) -> float:
        return self.steps_done / max(self.total_steps, 1)

    def describe(self) -> str:
        """One plain line, e.g. for a log file or a terminal-less run."""
        recent = "-" if self.recent_return is None else f"{self.recent_return:.2f}"
        return (
            f"{self.steps_done:,} / {self.total_steps:,} steps ({self.fraction:.1%}), chunk {self.chunk}/{self.chunks}, "
            f"recent return {recent}, {self.steps_per_s:,.0f} steps/s per model, ETA {format_duration(self.eta_s)}"
        )


def format_duration(seconds: float | None) -> str:
    """``1:02:03`` / ``2:03`` (``-`` when unknown)."""
    if seconds is None or not math.isfinite(seconds):
        return "-"
    total = round(max(seconds, 0.0))
    hours, rest = divmod(total, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


def recent_return(recent: np.ndarray, finished: np.ndarray) -> float | None:
    """The mean of the stored returns of the last finished episodes.

    Parameters
    ----------
    recent : array (..., RECENT_EPISODES)
        Each environment's ring of returns of its last finished episodes.
    finished : int array, broadcastable to ``recent.shape[:-1]``
        Episodes each environment finished (the ring holds ``min(finished, RECENT_EPISODES)``).
    """
    recent = np.asarray(recent, dtype=np.float64)
    finished = np.broadcast_to(np.asarray(finished), recent.shape[:-1])  # one count for all seeds, or one each
    filled = np.arange(recent.shape[-1]) < np.minimum(finished, recent.shape[-1])[..., None]
    return float(recent[filled].mean()) if filled.any() else None
