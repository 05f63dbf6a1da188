"""The Planner/Auditor governance layer (evaluation only; see docs/planner_auditor.md).

A :class:`~solarchain_eval.governance.wrapper.GovernedPolicy` wraps any policy: once per episode a
planner sets action bounds and an audit policy; each step the scheduler bounds the proposed
action, checks the hard and soft triggers against the budget and cooldown, and an auditor
approves or revises the selected steps. Planners: ``rule``, ``llm``, ``default``,
``calibrated-rule``; auditors: ``rule``, ``llm``, ``approve-only`` and the controls
``always-audit``, ``random``, ``oracle`` (docs/governance.md). LLM components call
:mod:`solarchain_eval.llm` with strict structured outputs; so does :class:`~.llm_agent.LLMAgent`,
the policy whose every action is the model's reply (docs/llm.md#llm-as-the-agent).
"""

from .factory import AgenticOptions, Governance, LLMOptions
from .llm_agent import LLMAgent, open_llm_agent
from .metrics import AGENTIC_METRIC_NAMES
from .wrapper import GovernedPolicy

__all__ = [
    "AGENTIC_METRIC_NAMES",
    "AgenticOptions",
    "Governance",
    "GovernedPolicy",
    "LLMAgent",
    "LLMOptions",
    "open_llm_agent",
]
