"""Prompts of the LLM Planner and Auditor, and of the LLM agent: the market's text and a JSON context.

The domain text (what the market is, what the levers mean, the units of the fields) is the
market's own: its governance view's :class:`~solarchain_eval.tasks.governance_view.GovernancePrompts`
(without one, the default task's). It never changes between runs; only the context (a JSON
object built from the episode or the step) is substituted. The context is serialised compactly
and in a fixed key order chosen for speed: what never changes within a run (the benchmark
ranges) comes first, then what is fixed within an episode (the Planner's policy), then what
changes every step. A server that keeps the previous request's tokens (llama.cpp's prompt cache)
then re-reads only the part after the shared prefix; on a CPU, reading the prompt is most of a
call's time (see docs/llm.md). Identical situations still give identical requests, which is what
makes the response cache work. The system prompt is the same for the Planner and the Auditor, so
a prefix-caching server re-reads only the user message, which names the role.
"""

from __future__ import annotations

import json
from typing import Any

from ..tasks.governance_view import GovernancePrompts
from .view import default_view

#: Names of the default task's prompt text, kept here for code that imported them from this module.
_DEFAULT_TEXT = {
    "SYSTEM": "system",
    "PLANNER_SYSTEM": "system",
    "AUDITOR_SYSTEM": "system",
    "PLANNER_INSTRUCTION": "planner_instruction",
    "AUDITOR_INSTRUCTION": "auditor_instruction",
    "AGENT_SYSTEM": "agent_system",
    "AGENT_INSTRUCTION": "agent_instruction",
    "AGENT_OBSERVATION_UNITS": "agent_observation_units",
    "AGENT_OUTCOME_UNITS": "agent_outcome_units",
}


def __getattr__(name: str) -> Any:
    if name in _DEFAULT_TEXT:
        return getattr(default_view().prompts, _DEFAULT_TEXT[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _text(prompts: GovernancePrompts | None) -> GovernancePrompts:
    return prompts if prompts is not None else default_view().prompts


def _user_message(instruction: str, context: dict[str, Any]) -> str:
    # Insertion order (fixed by the context builders), no whitespace: a third of the tokens of
    # an indented, key-sorted dump, and the shared prefix of consecutive calls stays long.
    body = json.dumps(context, separators=(",", ":"), ensure_ascii=False, allow_nan=False)
    return f"{instruction}\n\nContext (JSON):\n{body}"


def planner_messages(context: dict[str, Any], prompts: GovernancePrompts | None = None) -> list[dict[str, str]]:
    """System and user messages for the Planner, with the episode context substituted."""
    text = _text(prompts)
    return [
        {"role": "system", "content": text.system},
        {"role": "user", "content": _user_message(text.planner_instruction, context)},
    ]


def auditor_messages(context: dict[str, Any], prompts: GovernancePrompts | None = None) -> list[dict[str, str]]:
    """System and user messages for the Auditor, with the step context substituted."""
    text = _text(prompts)
    return [
        {"role": "system", "content": text.system},
        {"role": "user", "content": _user_message(text.auditor_instruction, context)},
    ]


def agent_messages(context: dict[str, Any], prompts: GovernancePrompts | None = None) -> list[dict[str, str]]:
    """System and user messages for the LLM agent, with the step context substituted."""
    text = _text(prompts)
    return [
        {"role": "system", "content": text.agent_system},
        {"role": "user", "content": _user_message(text.agent_instruction, context)},
    ]
