"""Build agents: the baselines and learned policies by name, and user agents from their specs (:mod:`.specs`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..common.redaction import redact_spec
from ..config import BenchmarkConfig
from ..market.baselines import BASELINES, make_baseline
from ..market.spaces import n_discrete_actions
from .adapters import AgentError, AgentFailure, SB3ModelAgent, as_agent
from .base import Policy
from .jax_checkpoint import register_jax_policies
from .sb3 import load_sb3_model, load_vecnormalize, register_learned_policies
from .specs import AgentSpec, AgentSpecError, instantiate, load_target, parse_agent_list

#: Factories for policies that need more than the config (e.g. trained models), by name.
#: Each takes (config, models) and returns a Policy; extra modules register themselves here.
EXTRA_POLICIES: dict[str, Callable[[BenchmarkConfig, dict[str, Path]], Policy]] = {}
register_learned_policies(EXTRA_POLICIES)  # "ppo", "sac", "dqn" (SB3 is imported only to load a model)
register_jax_policies(EXTRA_POLICIES)  # the same names also load JAX checkpoints (JAX imported only then)


def known_policies() -> tuple[str, ...]:
    return (*BASELINES, *EXTRA_POLICIES)


def user_agent(agent: Any, config: BenchmarkConfig) -> Any:
    """The runner's view of a user's agent object, its discrete indices checked against ``config``'s grid."""
    return as_agent(agent, discrete_actions=n_discrete_actions(config.discrete_levels))


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


def make_agent(
    spec: AgentSpec,
    config: BenchmarkConfig,
    *,
    models: dict[str, Path] | None = None,
    agent_args: dict[str | None, dict[str, Any]] | None = None,
    vecnormalize: dict[str | None, Path] | None = None,
) -> Policy:
    """Build the agent a spec names (any kind but ``llm``, which the evaluation runner builds).

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
        An import, attribute, constructor, model or action-mode problem, in one line.
    """
    discrete_actions = n_discrete_actions(config.discrete_levels)
    if spec.kind == "builtin":
        policy = make_policy(spec.target, config, models)
        if spec.name is not None and spec.name != policy.name:
            return as_agent(policy, name=spec.name, builtin=True, discrete_actions=discrete_actions)
        return policy
    if spec.kind == "llm":
        raise AgentSpecError(f"{spec.text!r}: the LLM agent is built by the evaluation, which owns its endpoint")
    name = spec.name
    kwargs = {**(agent_args or {}).get(None, {}), **(agent_args or {}).get(name, {})} if agent_args else {}
    try:
        if spec.kind == "sb3":
            algo, _, path = spec.target.partition(":")
            stats = (vecnormalize or {}).get(name) or (vecnormalize or {}).get(None)
            model = load_sb3_model(algo, path, config)
            agent = SB3ModelAgent(model, name=name, obs_normalizer=load_vecnormalize(stats) if stats else None)
            return as_agent(agent, discrete_actions=discrete_actions)
        if spec.kind == "http":
            from .http_agent import HttpAgent  # httpx is imported only for HTTP agents

            return as_agent(HttpAgent(name, spec.target, **kwargs), name=name, discrete_actions=discrete_actions)
        target, attr = load_target(spec)
        agent = instantiate(target, attr, spec, kwargs)
        return as_agent(agent, name=name or _own_name(agent) or attr, discrete_actions=discrete_actions)
    except AgentSpecError:
        raise
    except AgentFailure as error:  # already one line naming the agent (an HTTP agent's own errors)
        raise AgentSpecError(str(error)) from None
    except (AgentError, ValueError, TypeError, OSError) as error:
        raise AgentSpecError(f"agent {spec.label!r} ({redact_spec(spec.text)}): {error}") from None


def _own_name(agent: Any) -> str | None:
    name = getattr(agent, "name", None)
    return name if isinstance(name, str) and name.strip() else None


def parse_agents(text: str) -> list[AgentSpec]:
    """The specs of a ``--policies`` value (built-in names folded to lower case, the rest kept)."""
    return parse_agent_list(text, known_policies())
