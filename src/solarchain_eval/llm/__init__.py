"""Structured LLM calls: the OpenAI-SDK client, its record/replay cache, typed errors and deadline.

:class:`StructuredLLM` asks any OpenAI-compatible endpoint for one strict, schema-valid reply and
records or replays every exchange (:mod:`~solarchain_eval.llm.cache`); every failure is a typed
:class:`LLMError` naming its call site. :mod:`~solarchain_eval.llm.serving` runs the offline local
model server. Nothing here knows the market: the Planner/Auditor layer
(:mod:`solarchain_eval.governance`) and the LLM agent build on it.
"""

from .client import LLM_APIS, LLMSettings, StructuredLLM, resolve_llm_settings
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

__all__ = [
    "CallSite",
    "LLMCacheError",
    "LLMCacheMissError",
    "LLMConfigError",
    "LLMError",
    "LLMRefusalError",
    "LLMSchemaError",
    "LLMSettings",
    "LLMTransportError",
    "LLMTruncatedError",
    "LLM_APIS",
    "StructuredLLM",
    "resolve_llm_settings",
]
