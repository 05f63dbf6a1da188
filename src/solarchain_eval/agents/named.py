"""Agents built in by name: the task's baselines, the learned policies and the ``llm-agent``.

The baselines are the task's own (:meth:`~solarchain_eval.tasks.base.Task.baselines`), so this
wing names no market. Learned policies register a factory ``(config, models) -> Policy`` in
:data:`EXTRA_POLICIES`. The ``llm-agent``'s factory lives in the governance wing, above this one:
it is named here by its module path (data, imported on first use, as
:mod:`solarchain_eval.tasks.registry` names the built-in tasks).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..config import BenchmarkConfig
from ..tasks.registry import get_task
from .base import Policy
from .jax_checkpoint import register_jax_policies
from .sb3 import register_learned_policies

#: Factories for policies that need more than the config (e.g. trained models), by name.
#: Each takes (config, models) and returns a Policy; extra modules register themselves here.
EXTRA_POLICIES: dict[str, Callable[[BenchmarkConfig, dict[str, Path]], Policy]] = {}
register_learned_policies(EXTRA_POLICIES)  # "ppo", "sac", "dqn" (SB3 is imported only to load a model)
register_jax_policies(EXTRA_POLICIES)  # the same names also load JAX checkpoints (JAX imported only then)

#: The ``llm-agent``'s factory, ``(llm_options, market_config, *, name) -> agent``, as ``module:attribute``.
LLM_AGENT_FACTORY = "solarchain_eval.governance.llm_agent:open_llm_agent"


def baselines(task: str | None = None) -> dict[str, Callable[[Any], Policy]]:
    """The task's baselines by name, each a factory taking the config."""
    return dict(get_task(task).baselines())


def known_policies(task: str | None = None) -> tuple[str, ...]:
    """The built-in names: the task's baselines, then the learned policies."""
    return (*baselines(task), *EXTRA_POLICIES)


def make_policy(
    name: str, config: BenchmarkConfig, models: dict[str, Path] | None = None, *, task: str | None = None
) -> Policy:
    """The built-in policy ``name`` (case-insensitive): a baseline of the task, or a learned policy from ``models``.

    Raises
    ------
    ValueError
        No built-in has that name (the message lists them).
    FileNotFoundError
        A learned policy without a trained model (the message lists where it looked).
    """
    key = name.strip().lower()
    factories = baselines(task)
    if key in factories:
        return factories[key](config)
    if key in EXTRA_POLICIES:
        factory = EXTRA_POLICIES[key]
        # the learned policies check the model's spaces against the task's env; other factories take two
        return (
            factory(config, models or {}, task=task)
            if getattr(factory, "takes_task", False)
            else factory(config, models or {})
        )
    raise ValueError(f"unknown policy '{name}' (choose from {', '.join(known_policies(task))})")


def load_factory(target: str) -> Callable[..., Any]:
    """The object a ``module:attribute`` string names (imported now)."""
    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)
