"""The agents wing's registry: every agent, whatever its kind, is asked for with an
:class:`~.request.AgentRequest` and built by :func:`~.build.build_agents`.

What is registered where: built-in agents by name (the task's baselines, the learned policies of
:data:`EXTRA_POLICIES`, the ``llm-agent``) in :mod:`.named`; the builder of each kind of spec in
:data:`~.kinds.KIND_BUILDERS`. This module gathers the names callers use (``--policies`` parsing,
:func:`make_policy`, :func:`make_agent`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..config import BenchmarkConfig
from .adapters import as_agent, discrete_actions
from .base import Policy
from .build import build_agent, build_agents
from .kinds import KIND_BUILDERS, build_in_process
from .named import EXTRA_POLICIES, LLM_AGENT_FACTORY, known_policies, make_policy
from .request import AgentContext, AgentRequest, agent_request, agent_requests
from .specs import AgentSpec, parse_agent_list


def user_agent(agent: Any, config: BenchmarkConfig) -> Any:
    """The runner's view of a user's agent object, its discrete indices checked against ``config``'s grid."""
    return as_agent(agent, discrete_actions=discrete_actions(config))


def parse_policy_list(text: str) -> list[str]:
    names = [part.strip().lower() for part in text.split(",") if part.strip()]
    if not names:
        raise ValueError("no policies given")
    duplicates = {n for n in names if names.count(n) > 1}
    if duplicates:
        raise ValueError(f"policy listed twice: {', '.join(sorted(duplicates))}")
    return names


def make_agent(
    spec: AgentSpec,
    config: BenchmarkConfig,
    *,
    models: dict[str, Path] | None = None,
    agent_args: dict[str | None, dict[str, Any]] | None = None,
    vecnormalize: dict[str | None, Path] | None = None,
) -> Policy:
    """Build the agent a spec names in this process: :func:`~.kinds.build_in_process` of its request.

    Parameters
    ----------
    spec : AgentSpec
    config : BenchmarkConfig
        The evaluation's configuration (built-ins read the market; models are checked against it).
    models : dict, optional
        Trained models of the built-in learned policies (``--models``).
    agent_args : dict, optional
        ``--agent-arg`` options by agent name (None: every agent), for classes and factories.
    vecnormalize : dict, optional
        VecNormalize statistics by agent name (None: the only ``sb3:`` agent).

    Raises
    ------
    AgentSpecError
        An import, attribute, constructor, model or action-mode problem, in one line; the
        ``llm-agent``, whose endpoint only a request carries (:func:`~.request.agent_request` ``llm=``).
    """
    request = agent_request(spec, builtins=(), models=models, agent_args=agent_args, vecnormalize=vecnormalize)
    return build_in_process(request, AgentContext(config))


def parse_agents(text: str) -> list[AgentSpec]:
    """The specs of a ``--policies`` value (built-in names folded to lower case, the rest kept)."""
    return parse_agent_list(text, known_policies())


__all__ = [
    "EXTRA_POLICIES",
    "KIND_BUILDERS",
    "LLM_AGENT_FACTORY",
    "AgentContext",
    "AgentRequest",
    "agent_request",
    "agent_requests",
    "build_agent",
    "build_agents",
    "known_policies",
    "make_agent",
    "make_policy",
    "parse_agents",
    "parse_policy_list",
    "user_agent",
]
