"""Which episodes :mod:`.verify` re-runs: a seeded draw of (run seed, episode) pairs, and the
episodes a stateful agent must replay first to reach the state it had when they were recorded.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np


def default_seed(run_id: str) -> int:
    """The episode choice's seed of a run: the first 64 bits of the sha256 of its ``run_id``."""
    return int(hashlib.sha256(str(run_id).encode()).hexdigest()[:16], 16)


def choose_episodes(run_seeds: Sequence[int], episodes: int, k: int, seed: int) -> list[tuple[int, int]]:
    """``k`` distinct (run seed, episode) pairs drawn with ``numpy.random.default_rng(seed)``, in protocol order."""
    pairs = [(int(s), e) for s in run_seeds for e in range(episodes)]
    if k >= len(pairs):
        return pairs
    chosen = np.random.default_rng(seed).choice(len(pairs), size=k, replace=False)
    return [pairs[i] for i in sorted(int(i) for i in chosen)]


def replay_plan(
    chosen: Sequence[tuple[int, int]], run_seeds: Sequence[int], episodes: int, *, stateless: bool, carry_over: bool
) -> list[tuple[int, list[int]]]:
    """The episodes to run, by run seed in protocol order, so that each chosen one is run in the
    state the agent had when it was recorded.

    A stateless agent runs just the chosen episodes. Any other one runs its run seed's episodes
    in order up to the last one chosen; with ``carry_over`` (a run evaluated in order, one agent
    through all its run seeds) every earlier run seed's episodes first, as the runner did.
    """
    by_seed: dict[int, list[int]] = {}
    for run_seed, episode in chosen:
        by_seed.setdefault(int(run_seed), []).append(int(episode))
    if stateless:
        return [(s, sorted(w)) for s, w in by_seed.items()]
    if not carry_over:
        return [(s, list(range(max(w) + 1))) for s, w in by_seed.items()]
    seeds = [int(s) for s in run_seeds]
    last = max(seeds.index(s) for s in by_seed)
    return [(s, list(range(max(by_seed[s]) + 1 if i == last else episodes))) for i, s in enumerate(seeds[: last + 1])]
