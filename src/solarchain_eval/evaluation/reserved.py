"""Names reserved for the benchmark's own policies (docs/security.md#names).

They come from the registries of two wings, the agents' (baselines, learned algorithms,
``llm-agent``) and governance's (the Planner/Auditor kinds), so the rule lives here, above both.
"""

from __future__ import annotations

from ..agents.registry import known_policies
from ..agents.specs import LLM_AGENT, AgentSpecError
from ..governance.auditor import AUDITOR_KINDS
from ..governance.planner import PLANNER_KINDS


def reserved_names() -> tuple[str, ...]:
    """Names no user agent may take (in any case): the baselines, the learned algorithms, the LLM
    agent and the Planner/Auditor kinds, so that a row with one of these names is the benchmark's own."""
    return tuple(dict.fromkeys((*known_policies(), LLM_AGENT, *PLANNER_KINDS, *AUDITOR_KINDS)))


def check_reserved(name: str, builtin: str | None = None) -> None:
    """Refuse ``name`` for an agent that is not the built-in policy ``builtin`` when the name is
    reserved (:func:`reserved_names`, compared case-insensitively).

    Raises
    ------
    AgentSpecError
    """
    reserved = {r.lower(): r for r in reserved_names()}
    if name.lower() in reserved and name != builtin:
        raise AgentSpecError(
            f"agent name {name!r} is reserved for the benchmark's own {reserved[name.lower()]!r}: "
            "give your agent another name (NAME=spec, or name= in Python)"
        )
