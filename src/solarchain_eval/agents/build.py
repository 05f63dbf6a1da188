"""Build agents: one function for every kind, from :class:`~.request.AgentRequest` objects.

:func:`build_agents` is what an evaluation, ``verify``, the experiment grid and the governance
leaderboard call; each request goes through one of three doors:

- the benchmark's own policy object, passed from Python, is used as it is;
- a user's agent object, or a spec whose kind runs in a process of its own (``python``, ``file``,
  ``plugin``, ``sb3``) with ``isolate`` set, goes through the isolated door (:mod:`.isolated`);
- every other request is built here by its kind's builder (:mod:`.kinds`), an object wrapped by
  :func:`~.adapters.as_agent`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import ExitStack

from .adapters import as_agent, discrete_actions, is_builtin_policy
from .base import Policy
from .isolated import IsolatedAgent, is_isolatable
from .kinds import build_in_process
from .request import AgentContext, AgentRequest
from .specs import check_unique


def build_agent(request: AgentRequest, context: AgentContext) -> Policy:
    """The agent ``request`` asks for (see the module docstring); the caller closes it.

    Raises
    ------
    AgentSpecError
        A spec that cannot be built, or an object that cannot be isolated (one line naming it).
    AgentError
        An object that is no agent, or whose name breaks the naming rule.
    FileNotFoundError
        A learned built-in policy without a trained model.
    """
    if request.spec is None:
        agent = request.agent
        if is_builtin_policy(agent):  # the benchmark's own policy object, as its builder returns it
            return agent
        if request.isolate:
            return IsolatedAgent.from_object(agent)  # a copy in its own process
        return as_agent(agent, discrete_actions=discrete_actions(context.config, context.task))
    if request.isolate and is_isolatable(request.spec):
        return IsolatedAgent.from_request(request, context)
    return build_in_process(request, context)


def build_agents(
    requests: Sequence[AgentRequest],
    context: AgentContext,
    *,
    stack: ExitStack | None = None,
    check_name: Callable[[str, str | None], None] | None = None,
) -> list[Policy]:
    """The agents of ``requests``, in order, their names checked.

    Parameters
    ----------
    requests : sequence of AgentRequest
    context : AgentContext
    stack : ExitStack, optional
        Closes (their ``close`` hook) the agents built here, and the processes of isolated
        copies; agent objects the caller passed in are the caller's to close.
    check_name : callable, optional
        Called as ``check_name(name, builtin_name)`` for every agent but the benchmark's own
        policy objects, as soon as it is built (the evaluation's reserved names); raises to refuse.

    Raises
    ------
    AgentSpecError
        A request that cannot be built, or two agents with one name (their episodes would pool).
    """
    built: list[Policy] = []
    for request in requests:
        agent = build_agent(request, context)
        if request.spec is None and is_builtin_policy(request.agent):  # the benchmark's own object: the caller's
            built.append(agent)
            continue
        close = getattr(agent, "close", None)
        if stack is not None and close is not None and (request.spec is not None or request.isolate):
            stack.callback(close)
        if check_name is not None:
            check_name(agent.name, request.builtin_name)
        built.append(agent)
    check_unique([agent.name for agent in built])
    return built
