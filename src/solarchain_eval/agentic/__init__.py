"""The LLM Planner/Auditor layer (evaluation only; see docs/planner_auditor.md).

A :class:`~solarchain_eval.agentic.policy.GovernedPolicy` wraps any policy: once per episode a
planner sets action bounds and an audit policy; each step the scheduler bounds the proposed
action, checks the hard and soft triggers against the budget and cooldown, and an auditor
approves or revises the selected steps. Planners: ``rule``, ``llm``, ``default``,
``calibrated-rule``; auditors: ``rule``, ``llm``, ``approve-only`` and the controls
``always-audit``, ``random``, ``oracle`` (docs/governance.md). LLM components call any OpenAI-compatible endpoint with
strict structured outputs, and can record and replay every call
(:mod:`~solarchain_eval.agentic.cache`).
"""

from .build import AgenticOptions, Governance, LLMOptions
from .errors import (
    CallSite,
    LLMCacheError,
    LLMCacheMissError,
    LLMConfigError,
    LLMError,
    LLMRefusalError,
    LLMSchemaError,
    LLMTransportError,
    LLMTruncatedError,
)
from .llm_client import LLM_APIS, LLMSettings, StructuredLLM, resolve_llm_settings
from .metrics import AGENTIC_METRIC_NAMES
from .policy import GovernedPolicy

__all__ = [
    "AGENTIC_METRIC_NAMES",
    "AgenticOptions",
    "CallSite",
    "Governance",
    "GovernedPolicy",
    "LLMCacheError",
    "LLMCacheMissError",
    "LLMConfigError",
    "LLMError",
    "LLMOptions",
    "LLMRefusalError",
    "LLMSchemaError",
    "LLMSettings",
    "LLMTransportError",
    "LLMTruncatedError",
    "LLM_APIS",
    "StructuredLLM",
    "resolve_llm_settings",
]
