"""The paper's evaluation protocol in one place: seeds, episodes and the episode-seed rules.

Two results are comparable when they share these (and the dataset, setting and configuration):
every default that decides a number the paper prints lives here and nowhere else.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: The paper's seed: the dataset build, the default training seed and the first run seed.
PAPER_SEED = 20260511
#: The paper's three run (and training) seeds.
PAPER_SEEDS = (PAPER_SEED, PAPER_SEED + 1, PAPER_SEED + 2)
#: Evaluation episodes per run seed.
PAPER_EPISODES = 30
#: Hourly decisions per episode (then the episode is truncated).
EPISODE_HOURS = 24
#: Training steps per model in the paper.
PAPER_TIMESTEPS = 300_000

#: ``spawn_key`` of the SeedSequence behind the ``independent`` episode-seed rule ("EPIS").
EPISODE_SEED_SPAWN_KEY = 0x45504953


def paper_episode_seeds(run_seed: int, episodes: int) -> list[int]:
    """The paper's rule: episode e of a run with seed s is reset with seed s + e.

    Runs with neighbouring seeds therefore share start days (seed s's episode 1 is seed s + 1's
    episode 0); the report's statistics resample start days for that reason.
    """
    return [run_seed + e for e in range(episodes)]


def independent_episode_seeds(run_seed: int, episodes: int) -> list[int]:
    """Episode seeds that do not overlap across episodes or run seeds.

    Episode ``e`` of run seed ``s`` is reset with word ``e`` of
    ``numpy.random.SeedSequence(entropy=s, spawn_key=(0x45504953,)).generate_state(E, uint64)``
    shifted right by one bit (so it fits a signed 64-bit column). The words are a hash of
    ``(s, spawn key, e)``: the seeds of episodes 0..E-1 do not depend on E (more episodes extend
    the list), and two of them coincide with probability about n² / 2⁶⁴ for n seeds in a grid,
    which the grid checks anyway.
    """
    words = np.random.SeedSequence(entropy=int(run_seed), spawn_key=(EPISODE_SEED_SPAWN_KEY,)).generate_state(
        episodes, dtype=np.uint64
    )
    return [int(w >> np.uint64(1)) for w in words]


#: Episode-seed rules by name (``--episode-seeds``).
EPISODE_SEED_RULES: dict[str, Callable[[int, int], list[int]]] = {
    "paper": paper_episode_seeds,
    "independent": independent_episode_seeds,
}
#: Each rule in a few words (the ``--episode-seeds`` help); the same names as :data:`EPISODE_SEED_RULES`.
EPISODE_SEED_RULE_LINES: dict[str, str] = {
    "paper": "episode e of seed s uses s + e (seeds share episodes).",
    "independent": "non-overlapping seeds from a SeedSequence.",
}


def episode_seed_derivation(name: str) -> str:
    """How the rule ``name`` derives episode seeds, in words (a paper root's metadata records it):
    the paper's formula, else the second paragraph of the rule's docstring."""
    if name == "paper":
        return "episode e of run seed s is reset with seed s + e"
    paragraphs = (EPISODE_SEED_RULES[name].__doc__ or "").split("\n\n")
    return paragraphs[1].strip() if len(paragraphs) > 1 else ""


def episode_seed_rule_name(rule: Callable[[int, int], list[int]]) -> str:
    """The name a rule has in :data:`EPISODE_SEED_RULES` (``custom:<function name>`` otherwise)."""
    for name, known in EPISODE_SEED_RULES.items():
        if known is rule:
            return name
    return f"custom:{getattr(rule, '__name__', type(rule).__name__)}"
