"""Build policies by name: the baselines, and learned policies from saved models."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ..config import BenchmarkConfig
from ..market.baselines import BASELINES, make_baseline
from .base import Policy
from .jax_checkpoint import register_jax_policies
from .sb3 import register_learned_policies

#: Factories for policies that need more than the config (e.g. trained models), by name.
#: Each takes (config, models) and returns a Policy; extra modules register themselves here.
EXTRA_POLICIES: dict[str, Callable[[BenchmarkConfig, dict[str, Path]], Policy]] = {}
register_learned_policies(EXTRA_POLICIES)  # "ppo", "sac", "dqn" (SB3 is imported only to load a model)
register_jax_policies(EXTRA_POLICIES)  # the same names also load JAX checkpoints (JAX imported only then)


def known_policies() -> tuple[str, ...]:
    return (*BASELINES, *EXTRA_POLICIES)


def make_policy(name: str, config: BenchmarkConfig, models: dict[str, Path] | None = None) -> Policy:
    key = name.strip().lower()
    if key in BASELINES:
        return make_baseline(key, config.market)
    if key in EXTRA_POLICIES:
        return EXTRA_POLICIES[key](config, models or {})
    raise ValueError(f"unknown policy '{name}' (choose from {', '.join(known_policies())})")


def parse_policy_list(text: str) -> list[str]:
    names = [part.strip().lower() for part in text.split(",") if part.strip()]
    if not names:
        raise ValueError("no policies given")
    duplicates = {n for n in names if names.count(n) > 1}
    if duplicates:
        raise ValueError(f"policy listed twice: {', '.join(sorted(duplicates))}")
    return names
