"""What an agent is built from: one :class:`AgentRequest` per agent, one :class:`AgentContext` per evaluation.

Every kind of agent (a built-in baseline or learned policy, the ``llm-agent``, a ``module:attr``
or ``file.py:attr`` spec, an entry-point plugin, an ``sb3:`` model, an HTTP agent, an agent
object passed from Python) is asked for the same way: a request holds the spec (or the object)
and the options that agent is built with; :func:`~.build.build_agents` builds a list of them.
The command line's per-run options (``--agent-arg``, ``--vecnormalize``, ``--models``, the LLM
endpoint, ``--isolate``) become fields of each request here (:func:`agent_requests`), so they
travel as one object rather than as four mappings.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .named import known_policies
from .specs import LLM_AGENT, AgentSpec, parse_agent_spec


@dataclass(frozen=True)
class AgentContext:
    """What every agent of one evaluation is built against.

    Attributes
    ----------
    config : BenchmarkConfig
        The evaluation's configuration with its reward setting applied (built-ins read the market,
        models are checked against it, discrete actions against its grid).
    task : str or None
        The task's name (:func:`~solarchain_eval.tasks.registry.get_task`; None: the default task),
        whose baselines are the built-in agents.
    """

    config: Any
    task: str | None = None


@dataclass(frozen=True)
class AgentRequest:
    """One agent to build (see the module docstring); picklable, so the isolated door sends it as it is.

    Attributes
    ----------
    spec : AgentSpec or None
        The parsed spec (:mod:`.specs`); None when an agent object is passed.
    agent : object
        The agent object, function or SB3 model passed from Python (when ``spec`` is None).
    args : mapping
        The keyword arguments a class or factory is called with (``--agent-arg``: every agent's, then its own).
    vecnormalize : Path or None
        The VecNormalize statistics of an ``sb3:`` agent.
    models : mapping
        Trained models of the built-in learned policies (``--models``: ``{name: PATH}``, ``{"*": DIR}``).
    llm : LLMOptions or None
        The ``llm-agent``'s endpoint (:class:`~solarchain_eval.governance.factory.LLMOptions`).
    isolate : bool
        Build the agent in a process of its own (:mod:`.isolated`) when its kind allows it.
    """

    spec: AgentSpec | None = None
    agent: Any = None
    args: Mapping[str, Any] = field(default_factory=dict)
    vecnormalize: Path | None = None
    models: Mapping[str, Path] = field(default_factory=dict)
    llm: Any = None
    isolate: bool = False

    def __post_init__(self) -> None:
        if (self.spec is None) == (self.agent is None):
            raise ValueError("an agent request holds either a spec or an agent object")

    @property
    def builtin_name(self) -> str | None:
        """The built-in agent the spec names (``static``, ``llm-agent``), whose name only it may take; else None."""
        if self.spec is not None and self.spec.kind in ("builtin", "llm"):
            return self.spec.target
        return None

    @property
    def label(self) -> str:
        """The agent in messages: the spec's row name or target, else the object's type."""
        return self.spec.label if self.spec is not None else f"<{type(self.agent).__name__}>"


def agent_request(
    item: str | AgentSpec | Any,
    *,
    builtins: tuple[str, ...] | None = None,
    models: Mapping[str, Path] | None = None,
    agent_args: Mapping[str | None, Mapping[str, Any]] | None = None,
    vecnormalize: Mapping[str | None, Path] | None = None,
    llm: Any = None,
    isolate: bool = False,
    task: str | None = None,
) -> AgentRequest:
    """The request for one item of a policy list: a spec string (parsed), a parsed spec or an agent object.

    ``agent_args`` and ``vecnormalize`` are the command line's mappings by agent name (None: every
    agent, resp. the only ``sb3:`` agent); the request keeps the entries of its own agent.
    ``builtins`` are the built-in names (default: the task's baselines and the learned policies).

    Raises
    ------
    AgentSpecError
        A spec that cannot be read (one line naming it).
    """
    options: dict[str, Any] = {"models": dict(models or {}), "llm": llm, "isolate": isolate}
    if isinstance(item, str):
        item = parse_agent_spec(item, known_policies(task) if builtins is None else builtins)
    if not isinstance(item, AgentSpec):
        return AgentRequest(agent=item, **options)
    name = item.name
    args = {**(agent_args or {}).get(None, {}), **(agent_args or {}).get(name, {})} if agent_args else {}
    stats = (vecnormalize or {}).get(name) or (vecnormalize or {}).get(None)
    return AgentRequest(spec=item, args=args, vecnormalize=Path(stats) if stats else None, **options)


def agent_requests(
    items: Sequence[str | AgentSpec | Any],
    *,
    models: Mapping[str, Path] | None = None,
    agent_args: Mapping[str | None, Mapping[str, Any]] | None = None,
    vecnormalize: Mapping[str | None, Path] | None = None,
    llm: Any = None,
    isolate: bool = False,
    task: str | None = None,
) -> list[AgentRequest]:
    """:func:`agent_request` for each item of a policy list, with the same options."""
    builtins = known_policies(task)
    return [
        agent_request(
            item,
            builtins=builtins,
            models=models,
            agent_args=agent_args,
            vecnormalize=vecnormalize,
            llm=llm,
            isolate=isolate,
            task=task,
        )
        for item in items
    ]


__all__ = ["LLM_AGENT", "AgentContext", "AgentRequest", "agent_request", "agent_requests"]
