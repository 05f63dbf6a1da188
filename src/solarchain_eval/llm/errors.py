"""Typed LLM errors. Each one fails the run; nothing is ever substituted for a failed call.

Messages name the call site (planner, auditor or agent, policy, run seed, episode, step) and never
contain the API key: :func:`~solarchain_eval.common.redaction.remove_secret` removes it from any text that came
from the server.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..common.errors import InputDataError, NamesOptions, OptionsError, ServiceError, flag_of, render


@dataclass(frozen=True)
class CallSite:
    """Where an LLM call was made: ``step`` is None for the planner (called before step 0)."""

    kind: str  # "planner" | "auditor" | "agent" (the LLM agent)
    policy: str
    run_seed: int
    episode: int
    step: int | None = None

    def describe(self) -> str:
        where = "before step 0" if self.step is None else f"step {self.step}"
        return f"LLM {self.kind} for policy '{self.policy}', run seed {self.run_seed}, episode {self.episode}, {where}"


class LLMError(NamesOptions, RuntimeError):
    """Base class: an LLM call could not produce a valid structured output.

    Each subclass is also of one error type of :mod:`solarchain_eval.common.errors`: settings are
    an :class:`~solarchain_eval.common.errors.OptionsError`, the response cache an
    :class:`~solarchain_eval.common.errors.InputDataError`, the model's or endpoint's failures a
    :class:`~solarchain_eval.common.errors.ServiceError`.

    ``what`` and the detail may name options as ``{opt_<field>}`` (see :mod:`solarchain_eval.common.errors`).
    """

    what = "LLM call failed"

    def __init__(self, detail: str, site: CallSite | None = None) -> None:
        self.detail = detail
        self.site = site
        super().__init__(self._message())

    def _message(self, name_of: Callable[[str], str] | None = None) -> str:
        prefix = f"{self.site.describe()}: " if self.site is not None else ""
        detail = self.detail if self.template is None else render(self.template, self.values, name_of)
        return f"{prefix}{render(self.what, {}, name_of)}: {detail}"

    def message_for(self, name_of: Callable[[str], str] = flag_of) -> str:
        return self._message(name_of)

    def at(self, site: CallSite) -> LLMError:
        """The same error, located at ``site``."""
        located = type(self)(self.detail, site)
        located.template, located.values = self.template, self.values
        return located


class LLMConfigError(LLMError, OptionsError):
    what = "LLM settings are incomplete"


class LLMRefusalError(LLMError, ServiceError):
    what = "the model refused"


class LLMTruncatedError(LLMError, ServiceError):
    what = "the output was truncated (raise {opt_llm_max_output_tokens})"


class LLMSchemaError(LLMError, ServiceError):
    what = "the output does not match the required schema"


class LLMTransportError(LLMError, ServiceError):
    what = "the endpoint could not be reached or answered with an error (after retries)"


class LLMCacheMissError(LLMError, InputDataError):
    what = "no recorded response for this request in replay mode"


class LLMCacheError(LLMError, InputDataError):
    what = "the response cache is unusable"
