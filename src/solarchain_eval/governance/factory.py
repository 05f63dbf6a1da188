"""Options of the agentic layer and the factory that wraps policies with it."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from ..agents.base import Policy
from ..llm.client import LLMSettings, StructuredLLM
from ..llm.errors import LLMConfigError
from ..tasks.governance_view import GovernanceView, LeverCodec
from .auditor import AUDITOR_KINDS, ApproveOnlyAuditor, Auditor, LLMAuditor, RuleAuditor
from .calibrated import DEFAULT_TARGET_AUDIT_RATE, CalibratedRulePlanner
from .controls import DEFAULT_ORACLE_REWARD_LOSS, AlwaysAuditAuditor, OracleAuditor, RandomAuditor, SchedulerControls
from .errors import GovernanceConfigError
from .planner import PLANNER_KINDS, DefaultPlanner, LLMPlanner, Planner, RulePlanner
from .view import resolve_view
from .wrapper import GovernedPolicy


@dataclass(frozen=True)
class LLMOptions:
    """Endpoint settings and the record/replay cache of the LLM components."""

    settings: LLMSettings
    cache_dir: Path | None = None
    cache_mode: str = "off"

    @classmethod
    def replaying(cls, described: Mapping[str, Any], cache_dir: Path | str) -> LLMOptions:
        """Options that replay, from ``cache_dir``, the calls of a run whose settings
        :meth:`describe` recorded (no endpoint, no key)."""
        names = {f.name for f in fields(LLMSettings)} - {"api_key"}
        settings = LLMSettings(**{k: v for k, v in described.items() if k in names})
        return cls(settings=settings, cache_dir=Path(cache_dir), cache_mode="replay")

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
    planner : {"rule", "llm", "default", "calibrated-rule"}
    auditor : {"rule", "llm", "approve-only", "always-audit", "random", "oracle"}
    llm : LLMOptions, optional
        Required when the planner or the auditor is ``llm``.
    controls : SchedulerControls
        Trigger ablation and budget/cooldown overrides (docs/governance.md#controls).
    diagnostics : bool
        Record counterfactual step records (``governance_diagnostics.csv``; on by default, so the
        report's governance section has them whenever a run has agentic logs).
    target_audit_rate : float
        The calibrated rule planner's target audit rate.
    random_audit_rate : float or mapping of policy -> float, optional
        The random auditor's audit rate (default: the plan's budget B per episode).
    random_seed : int
        Seed of the random auditor's step choice.
    random_audit_counts : mapping of (policy, run seed, episode) -> int, optional
        Audits per episode for the random auditor to match exactly (e.g. a reference run's).
    oracle_reward_loss : float
        The oracle auditor's reward-loss bound per audited step.
    """

    planner: str = "rule"
    auditor: str = "rule"
    llm: LLMOptions | None = None
    controls: SchedulerControls = field(default_factory=SchedulerControls)
    diagnostics: bool = True
    target_audit_rate: float = DEFAULT_TARGET_AUDIT_RATE
    random_audit_rate: float | Mapping[str, float] | None = None
    random_seed: int = 0
    random_audit_counts: Mapping[tuple[str, int, int], int] | None = None
    oracle_reward_loss: float = DEFAULT_ORACLE_REWARD_LOSS

    def __post_init__(self) -> None:
        if self.planner not in PLANNER_KINDS:
            raise GovernanceConfigError(f"unknown planner {self.planner!r} (choose from {', '.join(PLANNER_KINDS)})")
        if self.auditor not in AUDITOR_KINDS:
            raise GovernanceConfigError(f"unknown auditor {self.auditor!r} (choose from {', '.join(AUDITOR_KINDS)})")
        if self.uses_llm and self.llm is None:
            raise LLMConfigError.about(
                "an LLM planner or auditor needs LLM settings ({opt_llm_api}, {opt_llm_model}, ...)"
            )

    @property
    def uses_llm(self) -> bool:
        return self.planner == "llm" or self.auditor == "llm"

    def describe(self) -> dict[str, Any]:
        described: dict[str, Any] = {
            "mode": "planner_auditor",
            "planner": self.planner,
            "auditor": self.auditor,
            "llm": self.llm.describe() if (self.llm is not None and self.uses_llm) else None,
        }
        # What differs from the paper's layer only, so default runs describe themselves as before.
        if not self.controls.is_default:
            described["controls"] = self.controls.describe()
        if not self.diagnostics:
            described["diagnostics"] = False
        if self.planner == "calibrated-rule":
            described["target_audit_rate"] = self.target_audit_rate
        if self.auditor == "random":
            rate = self.random_audit_rate
            described["random_audit_rate"] = dict(rate) if isinstance(rate, Mapping) else rate
            described["random_seed"] = self.random_seed
            if self.random_audit_counts:
                described["random_audit_counts"] = {
                    f"{policy}/{seed}/{episode}": int(n)
                    for (policy, seed, episode), n in self.random_audit_counts.items()
                }
        if self.auditor == "oracle":
            described["oracle_reward_loss"] = self.oracle_reward_loss
        return described

    @classmethod
    def from_record(cls, record: Mapping[str, Any], *, llm_cache: Path | None = None) -> AgenticOptions:
        """The options a run's metadata describes (the inverse of :meth:`describe`).

        LLM components are rebuilt to *replay* their calls from the record/replay cache
        ``llm_cache`` (no endpoint, no key); without it they cannot be rebuilt.

        Raises
        ------
        GovernanceConfigError
            An unknown planner, auditor or trigger set, or a control out of range.
        LLMConfigError
            LLM components without ``llm_cache``.
        """
        llm: LLMOptions | None = None
        described_llm = record.get("llm")
        if isinstance(described_llm, Mapping):
            if llm_cache is None:
                raise LLMConfigError.about("the run's LLM calls can only be replayed: pass {opt_llm_cache} DIR")
            llm = LLMOptions.replaying(described_llm, llm_cache)
        controls = record.get("controls") or {}
        rate = record.get("random_audit_rate")
        counts = record.get("random_audit_counts") or None
        if counts is not None:  # "policy/run seed/episode" -> n (policy names hold no "/")
            counts = {
                (key.rsplit("/", 2)[0], int(key.rsplit("/", 2)[1]), int(key.rsplit("/", 2)[2])): int(n)
                for key, n in counts.items()
            }
        return cls(
            planner=str(record.get("planner", "rule")),
            auditor=str(record.get("auditor", "rule")),
            llm=llm,
            controls=SchedulerControls(**controls),
            diagnostics=bool(record.get("diagnostics", True)),
            target_audit_rate=float(record.get("target_audit_rate", DEFAULT_TARGET_AUDIT_RATE)),
            random_audit_rate=dict(rate) if isinstance(rate, Mapping) else rate,
            random_seed=int(record.get("random_seed", 0)),
            random_audit_counts=counts,
            oracle_reward_loss=float(record.get("oracle_reward_loss", DEFAULT_ORACLE_REWARD_LOSS)),
        )

    def label(self) -> str:
        """What ran, e.g. "rule planner, oracle auditor" or "rule planner, llm:gpt-4o auditor"."""
        model = self.llm.settings.model if self.llm is not None else None

        def name(kind: str) -> str:
            return f"llm:{model}" if kind == "llm" and model else kind

        return f"{name(self.planner)} planner, {name(self.auditor)} auditor"


class Governance:
    """Wraps policies with one planner and auditor; owns the shared LLM client.

    Use as a context manager (or call :meth:`close`) so the HTTP client is released.

    Parameters
    ----------
    options : AgenticOptions
    view : GovernanceView or config
        The governed market's view (``task.governance_view(config)``); a benchmark config or its
        market section stands for the default task's view of it (the solar market).
    """

    def __init__(self, options: AgenticOptions, view: Any) -> None:
        self.options = options
        self.view: GovernanceView = resolve_view(view)
        codec = self.view.codec
        described = self.view.prompts.lever_descriptions
        self.levers = tuple((name, described.get(name, name)) for name in self.view.lever_names)
        self.client: StructuredLLM | None = None
        if options.uses_llm:
            assert options.llm is not None
            self.client = StructuredLLM(
                options.llm.settings, cache_dir=options.llm.cache_dir, cache_mode=options.llm.cache_mode
            )
        self.planner = self._planner(options.planner, codec)
        self.auditor = self._auditor(options.auditor, codec)

    def _planner(self, kind: str, codec: LeverCodec) -> Planner:
        if kind == "rule":
            return RulePlanner(codec, self.levers)
        if kind == "default":
            return DefaultPlanner(codec, self.levers)
        if kind == "calibrated-rule":
            return CalibratedRulePlanner(codec, self.options.target_audit_rate, self.levers)
        assert self.client is not None
        return LLMPlanner(self.client, codec, self.view.prompts, self.levers)

    def _auditor(self, kind: str, codec: LeverCodec) -> Auditor:
        if kind == "rule":
            return RuleAuditor(codec)
        if kind == "approve-only":
            return ApproveOnlyAuditor()
        if kind == "always-audit":
            return AlwaysAuditAuditor(codec)
        if kind == "random":
            return RandomAuditor(
                codec, self.options.random_audit_rate, self.options.random_seed, self.options.random_audit_counts
            )
        if kind == "oracle":
            return OracleAuditor(codec, self.options.oracle_reward_loss, self.view)
        assert self.client is not None
        return LLMAuditor(self.client, codec, self.view.prompts, self.levers)

    def wrap(self, policy: Policy) -> GovernedPolicy:
        return GovernedPolicy(
            policy,
            self.planner,
            self.auditor,
            controls=self.options.controls,
            diagnostics=self.options.diagnostics,
            view=self.view,
        )

    def close(self) -> None:
        if self.client is not None:
            self.client.close()

    def __enter__(self) -> Governance:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
