"""How each kind of agent spec is built in this process: one builder per kind, in :data:`KIND_BUILDERS`.

A builder takes an :class:`~.request.AgentRequest` and the evaluation's
:class:`~.request.AgentContext` and returns the agent. :func:`build_in_process` picks the
builder of the request's kind and turns whatever a user's code or file raises into one
:class:`~.specs.AgentSpecError` line naming the agent. The isolated door (:mod:`.isolated`) calls
it in the agent's own process; :func:`~.build.build_agent` decides which door a request takes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..common.redaction import redact_spec
from ..tasks.base import observation_names_of
from ..tasks.governance_view import governance_view_of
from ..tasks.registry import get_task
from .adapters import AgentError, AgentFailure, SB3ModelAgent, as_agent, discrete_actions
from .base import Policy
from .named import LLM_AGENT_FACTORY, load_factory, make_policy
from .request import AgentContext, AgentRequest
from .sb3 import load_sb3_model, load_vecnormalize
from .specs import LLM_AGENT, AgentSpecError, instantiate, load_target


def _builtin(request: AgentRequest, context: AgentContext) -> Policy:
    spec = request.spec
    assert spec is not None
    policy = make_policy(spec.target, context.config, dict(request.models), task=context.task)
    if spec.name is not None and spec.name != policy.name:  # mine=static: the built-in under another name
        grid = discrete_actions(context.config, context.task)
        return as_agent(policy, name=spec.name, builtin=True, discrete_actions=grid)
    return policy


def _llm(request: AgentRequest, context: AgentContext) -> Policy:
    spec = request.spec
    assert spec is not None
    if request.llm is None:
        raise AgentSpecError.about(
            "the llm-agent needs a model endpoint: {opt_llm_backend} local, or {opt_llm_api} URL with {opt_llm_model}"
        )
    open_llm_agent = load_factory(LLM_AGENT_FACTORY)
    return open_llm_agent(
        request.llm, governance_view_of(get_task(context.task), context.config), name=spec.name or LLM_AGENT
    )


def _sb3(request: AgentRequest, context: AgentContext) -> Policy:
    spec = request.spec
    assert spec is not None
    algo, _, path = spec.target.partition(":")
    model = load_sb3_model(algo, path, context.config, context.task)
    stats = load_vecnormalize(request.vecnormalize) if request.vecnormalize else None
    agent = SB3ModelAgent(model, name=spec.name, obs_normalizer=stats)
    return as_agent(agent, discrete_actions=discrete_actions(context.config, context.task))


def _http(request: AgentRequest, context: AgentContext) -> Policy:
    from .http_agent import HttpAgent  # httpx is imported only for HTTP agents

    spec = request.spec
    assert spec is not None and spec.name is not None  # the spec parser requires NAME= for a URL
    agent = HttpAgent(spec.name, spec.target, **request.args)
    agent.observation_names = observation_names_of(get_task(context.task))
    return as_agent(agent, name=spec.name, discrete_actions=discrete_actions(context.config, context.task))


def _from_code(request: AgentRequest, context: AgentContext) -> Policy:
    """A ``module:attr``, ``file.py:attr`` or plugin spec: the class or factory called with the request's args."""
    spec = request.spec
    assert spec is not None
    target, attr = load_target(spec)
    agent = instantiate(target, attr, spec, dict(request.args))
    name = spec.name or _own_name(agent) or attr
    return as_agent(agent, name=name, discrete_actions=discrete_actions(context.config, context.task))


def _own_name(agent: Any) -> str | None:
    name = getattr(agent, "name", None)
    return name if isinstance(name, str) and name.strip() else None


#: Every kind of spec (:data:`~.specs.AGENT_KINDS`) and its builder.
KIND_BUILDERS: dict[str, Callable[[AgentRequest, AgentContext], Policy]] = {
    "builtin": _builtin,
    "llm": _llm,
    "python": _from_code,
    "file": _from_code,
    "plugin": _from_code,
    "sb3": _sb3,
    "http": _http,
}
#: Kinds that run a user's code or read a user's file: what they raise becomes one line naming the agent.
USER_KINDS = ("python", "file", "plugin", "sb3", "http")


def build_in_process(request: AgentRequest, context: AgentContext) -> Policy:
    """The agent of a spec request, built in this process by its kind's builder.

    Raises
    ------
    AgentSpecError
        An import, attribute, constructor, model or action-mode problem, in one line.
    FileNotFoundError
        A learned built-in policy without a trained model (the message lists where it looked).
    """
    spec = request.spec
    if spec is None:
        raise ValueError("build_in_process builds spec requests; an agent object is built by build_agent")
    builder = KIND_BUILDERS[spec.kind]
    if spec.kind not in USER_KINDS:
        return builder(request, context)
    try:
        return builder(request, context)
    except AgentSpecError:
        raise
    except AgentFailure as error:  # already one line naming the agent (an HTTP agent's own errors)
        raise AgentSpecError(str(error)) from None
    except (AgentError, ValueError, TypeError, OSError) as error:
        raise AgentSpecError(f"agent {spec.label!r} ({redact_spec(spec.text)}): {error}") from None
