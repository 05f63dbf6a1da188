"""How ``verify`` rebuilds what a run recorded: each policy's agent, from the caller's specs or
the recorded ones, and the Planner/Auditor options, or a reason why it cannot.

Policies are rebuilt as the evaluation runner builds them, a user agent only from a spec the
caller gives and in a process of its own; the run's metadata never decides what code runs
(docs/security.md).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from ..agents.base import Policy
from ..agents.build import build_agents
from ..agents.registry import known_policies
from ..agents.request import AgentContext, agent_requests
from ..agents.specs import AgentSpecError, parse_agent_spec
from ..governance.errors import GovernanceConfigError
from ..governance.factory import AgenticOptions, LLMOptions
from ..llm.errors import LLMError
from ..tasks.base import Task
from ..tasks.registry import DEFAULT_TASK
from .reserved import check_reserved
from .run_metadata import RunMetadata
from .verify_checks import VerifyError


def agent_builder(
    text: str,
    config: Any,
    models: dict[str, Path],
    agent_args: dict[str | None, dict[str, Any]],
    stack: ExitStack,
    task: str = DEFAULT_TASK,
) -> Callable[[], Policy]:
    """A function building the agent of spec ``text`` in ``task`` as the evaluation runner builds it."""
    # a submitted agent is re-run in its own process, where it cannot reach the env
    return _build_one(text, config, stack, task=task, models=models, agent_args=agent_args, isolate=True)


def _build_one(
    text: str, config: Any, stack: ExitStack, *, task: str = DEFAULT_TASK, **options: Any
) -> Callable[[], Policy]:
    """A function building the agent of spec ``text`` in ``task`` with the request ``options``, closed by ``stack``."""
    context = AgentContext(config, task)
    return lambda: build_agents(
        agent_requests([text], task=task, **options), context, stack=stack, check_name=check_reserved
    )[0]


def recorded_builder(
    text: str,
    config: Any,
    models: dict[str, Path],
    stack: ExitStack,
    *,
    agent_args: dict[str | None, dict[str, Any]],
    llm_cache: Path | None,
    llm_agent: Mapping[str, Any] | None = None,
    task: Task | None = None,
) -> Callable[[], Policy] | str:
    """How to rebuild a policy from its recorded spec, or why it cannot be rebuilt.

    ``agent_args`` are the ``--agent-arg`` options by agent name, ``llm_cache`` the cache an
    ``llm-agent``'s calls are replayed from, ``llm_agent`` its recorded endpoint.
    """
    if task is not None and task.name != DEFAULT_TASK and text in task.baselines():
        return agent_builder(text, config, models, agent_args, stack, task.name)  # the installed task's own baseline
    if text.startswith("<"):
        return f"an agent object {text} passed from Python; pass its spec with --agent NAME=module:attr"
    try:
        parsed = parse_agent_spec(text, known_policies())
    except AgentSpecError as error:
        return f"recorded spec {text!r}: {error}; pass its spec with --agent"
    if parsed.kind == "builtin":
        return agent_builder(text, config, models, agent_args, stack)
    if parsed.kind == "llm":
        if not llm_agent:
            return "the llm-agent's endpoint is not recorded in the run"
        if llm_cache is None:
            return "LLM calls; pass --llm-cache"
        return _build_one(text, config, stack, llm=LLMOptions.replaying(llm_agent, llm_cache))
    return f"a user agent ({text}); pass its spec with --agent to rebuild it"


def given_builders(
    metadata: RunMetadata,
    config: Any,
    models: dict[str, Path],
    stack: ExitStack,
    *,
    agents: Sequence[str],
    agent_args: dict[str | None, dict[str, Any]],
) -> dict[str, Callable[[], Policy]]:
    """The builders of the agents given with ``--agent`` (specs ``agents``), by the name they build
    (checked before any work).

    Raises
    ------
    VerifyError
        A spec that cannot be built, or one building an agent the run does not name.
    """
    names = metadata.policies
    given: dict[str, Callable[[], Policy]] = {}
    for text in agents:
        build = agent_builder(text, config, models, agent_args, stack, metadata.task)
        try:
            name = build().name
        except (ValueError, OSError) as error:  # AgentSpecError, a model that cannot load, a missing file
            raise VerifyError.about("{opt_agents} {text}: {error}", text=text, error=error) from None
        if name not in names:
            raise VerifyError.about(
                "{opt_agents} {text} builds agent {name!r}; the run's policies are {names}",
                text=text,
                name=name,
                names=", ".join(names),
            )
        given[name] = build
    return given


def recorded_agentic(metadata: RunMetadata, llm_cache: Path | None) -> AgenticOptions | str | None:
    """The recorded Planner/Auditor options (None: not governed), or why they cannot be rebuilt
    (their LLM calls are replayed from ``llm_cache``)."""
    record = metadata.agentic
    if record is None:
        return None
    if record.get("llm") is not None and llm_cache is None:
        return "LLM calls; pass --llm-cache"
    try:
        return AgenticOptions.from_record(record, llm_cache=llm_cache)
    except (GovernanceConfigError, LLMError, TypeError, ValueError) as error:
        return f"the recorded Planner/Auditor options: {error}"
