"""Options of the agentic layer and the factory that wraps policies with it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..config import MarketConfig
from ..market.actions import ActionCodec
from ..policies.base import Policy
from .auditor import AUDITOR_KINDS, ApproveOnlyAuditor, Auditor, LLMAuditor, RuleAuditor
from .errors import LLMConfigError
from .llm_client import LLMSettings, StructuredLLM
from .planner import PLANNER_KINDS, DefaultPlanner, LLMPlanner, Planner, RulePlanner
from .policy import GovernedPolicy


@dataclass(frozen=True)
class LLMOptions:
    """Endpoint settings and the record/replay cache of the LLM components."""

    settings: LLMSettings
    cache_dir: Path | None = None
    cache_mode: str = "off"

    def describe(self) -> dict[str, Any]:
        return {
            **self.settings.describe(),
            "cache_dir": str(self.cache_dir) if self.cache_dir is not None else None,
            "cache_mode": self.cache_mode,
        }


@dataclass(frozen=True)
class AgenticOptions:
    """Which planner and auditor govern the policies (``rule`` by default: no endpoint needed).

    Parameters
    ----------
    planner : {"rule", "llm", "default"}
    auditor : {"rule", "llm", "approve-only"}
    llm : LLMOptions, optional
        Required when the planner or the auditor is ``llm``.
    """

    planner: str = "rule"
    auditor: str = "rule"
    llm: LLMOptions | None = None

    def __post_init__(self) -> None:
        if self.planner not in PLANNER_KINDS:
            raise LLMConfigError(f"unknown planner {self.planner!r} (choose from {', '.join(PLANNER_KINDS)})")
        if self.auditor not in AUDITOR_KINDS:
            raise LLMConfigError(f"unknown auditor {self.auditor!r} (choose from {', '.join(AUDITOR_KINDS)})")
        if self.uses_llm and self.llm is None:
            raise LLMConfigError.about(
                "an LLM planner or auditor needs LLM settings ({opt_llm_api}, {opt_llm_model}, ...)"
            )

    @property
    def uses_llm(self) -> bool:
        return self.planner == "llm" or self.auditor == "llm"

    def describe(self) -> dict[str, Any]:
        return {
            "mode": "planner_auditor",
            "planner": self.planner,
            "auditor": self.auditor,
            "llm": self.llm.describe() if (self.llm is not None and self.uses_llm) else None,
        }


class Governance:
    """Wraps policies with one planner and auditor; owns the shared LLM client.

    Use as a context manager (or call :meth:`close`) so the HTTP client is released.
    """

    def __init__(self, options: AgenticOptions, market: MarketConfig) -> None:
        self.options = options
        codec = ActionCodec.from_config(market)
        self.client: StructuredLLM | None = None
        if options.uses_llm:
            assert options.llm is not None
            self.client = StructuredLLM(
                options.llm.settings, cache_dir=options.llm.cache_dir, cache_mode=options.llm.cache_mode
            )
        self.planner = self._planner(options.planner, codec)
        self.auditor = self._auditor(options.auditor, codec)

    def _planner(self, kind: str, codec: ActionCodec) -> Planner:
        if kind == "rule":
            return RulePlanner(codec)
        if kind == "default":
            return DefaultPlanner(codec)
        assert self.client is not None
        return LLMPlanner(self.client, codec)

    def _auditor(self, kind: str, codec: ActionCodec) -> Auditor:
        if kind == "rule":
            return RuleAuditor(codec)
        if kind == "approve-only":
            return ApproveOnlyAuditor()
        assert self.client is not None
        return LLMAuditor(self.client, codec)

    def wrap(self, policy: Policy) -> GovernedPolicy:
        return GovernedPolicy(policy, self.planner, self.auditor)

    def close(self) -> None:
        if self.client is not None:
            self.client.close()

    def __enter__(self) -> Governance:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
