"""Auditors: called for the steps the scheduler selects; they approve or revise ā.

- ``rule``: docs/planner_auditor.md#rule-auditor, in float32 arithmetic. If ν > τν: α × 0.85, ℓ × 0.90,
  b = max(b, 0.12); if gap < τΔ: ℓ = max(ℓ, 0.80), α × 0.90; if κ > τκ: a = 0.6 a_prev + 0.4 a;
  then sanitise; "revise" when the result moved by more than 1e-6 (L1), else "approve".
  The three conditions are re-tested from the step context in float64 (the float32 signals
  widened, the thresholds as given), not taken from the scheduler's float32 triggers: on a tie
  such as ν = float32(0.14) against τν = 0.14 no hard trigger fires, yet an audit called by
  the soft trigger still applies the physics revision, as the original release did.
- ``approve-only``: always approves (isolates the effect of the Planner's bounds).
- ``llm``: the model's structured verdict; a revised action is sanitised (each clip logged).

``approve`` keeps ā; ``revise`` executes the sanitised final action.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ..llm.client import StructuredLLM
from ..llm.errors import CallSite
from ..tasks.governance_view import GovernancePrompts, LeverCodec
from .planner import benchmark_ranges
from .prompts import auditor_messages
from .scheduler import Action, action_delta
from .schemas import Levers, Plan, output_models, validate_audit

AUDITOR_KINDS = ("rule", "llm", "approve-only", "always-audit", "random", "oracle")
#: Observation fields the auditor prompt leaves out: they repeat ``hour_of_day`` and ``previous_action``.
PROMPT_OMITTED_OBSERVATIONS = ("hour_sin", "hour_cos", "prev_reward_ratio", "prev_liquidity_ratio")
REVISION_TOLERANCE = 1e-6  # L1 distance below which a rule revision counts as "approve"

_F32 = np.float32


@dataclass(frozen=True)
class StepContext:
    """What an auditor sees at one step (actions in market units, float32 values).

    ``observation`` holds the named observation fields; ``recent`` the previous step's market
    outcome (None at step 0).
    """

    step: int
    hour: int
    observation: dict[str, float]
    violation_rate: float
    supply_gap: float
    static_slippage: float
    bounded_action: Action
    previous_action: Action
    kappa: float
    plan: Plan
    hard_reasons: tuple[str, ...]
    soft_trigger: bool
    recent: dict[str, float] | None
    #: The step's counterfactual evaluator (market-unit action -> the market's outcome from the
    #: same state and price shock; docs/governance.md); never shown to a model.
    counterfactual: Callable[[Action], Any] | None = field(default=None, compare=False, repr=False)

    def to_prompt(self, codec: LeverCodec) -> dict[str, Any]:
        def named(action: Action) -> dict[str, float]:
            return {name: round(float(v), 6) for name, v in zip(self.plan.lever_names, action, strict=True)}

        policy = self.plan.to_log()
        del policy["rationale"]  # model-written free text: long, and nothing to decide on
        # Keys from the most to the least stable (run, episode, step): consecutive audits share
        # a long prompt prefix. hour_sin/hour_cos (hour_of_day) and prev_*_ratio
        # (previous_action) repeat what the context states directly.
        observation = {
            k: float(f"{v:.6g}") for k, v in self.observation.items() if k not in PROMPT_OMITTED_OBSERVATIONS
        }
        return {
            "benchmark_ranges": benchmark_ranges(codec, self.plan.lever_names),
            "planner_policy": policy,
            "step": self.step,
            "hour_of_day": self.hour,
            "triggers": {"hard": list(self.hard_reasons), "soft_jitter": self.soft_trigger},
            "observation": observation,
            "previous_hour_outcome": (
                None if self.recent is None else {k: float(f"{v:.6g}") for k, v in self.recent.items()}
            ),
            "previous_action": named(self.previous_action),
            "bounded_proposed_action": named(self.bounded_action),
            "action_change_l1": round(self.kappa, 6),
        }


@dataclass(frozen=True)
class AuditOutcome:
    decision: str  # "approve" | "revise"
    final_action: Action
    reason: str
    llm: dict[str, Any] | None = None  # call metadata and clip events (LLM auditor only)


class Auditor(Protocol):
    kind: str

    def audit(self, context: StepContext, site: CallSite) -> AuditOutcome: ...


def rule_risks(context: StepContext) -> tuple[bool, bool, bool]:
    """(ν > τν, gap < τΔ, κ > τκ) in float64: float32 signals widened, float64 thresholds.

    Deliberately not the scheduler's float32 comparisons; the two differ on ties.
    """
    plan = context.plan
    return (
        float(context.violation_rate) > float(plan.violation_threshold),
        float(context.supply_gap) < float(plan.gap_threshold),
        float(context.kappa) > float(plan.jitter_threshold),
    )


def rule_revision(context: StepContext, codec: LeverCodec) -> tuple[Action, list[str]]:
    """The rule auditor's revised action (sanitised float32) and the risks that drove it."""
    physics, liquidity, jitter = rule_risks(context)
    a = np.array(context.bounded_action, dtype=_F32)
    risks = []
    if physics:
        risks.append("physics")
        a[0] = a[0] * _F32(0.85)
        a[1] = a[1] * _F32(0.90)
        a[2] = max(a[2], _F32(min(0.12, codec.hi[2])))
    if liquidity:
        risks.append("liquidity")
        a[1] = max(a[1], _F32(min(0.80, codec.hi[1])))
        a[0] = a[0] * _F32(0.90)
    if jitter:
        risks.append("jitter")
        previous = np.array(context.previous_action, dtype=_F32)
        a = _F32(0.6) * previous + _F32(0.4) * a  # float32 throughout
    return codec.sanitize(float(a[0]), float(a[1]), float(a[2])), risks


class RuleAuditor:
    """The rule auditor (docs/planner_auditor.md#rule-auditor), in float32 arithmetic."""

    kind = "rule"

    def __init__(self, codec: LeverCodec) -> None:
        self.codec = codec

    def audit(self, context: StepContext, site: CallSite) -> AuditOutcome:
        revised, risks = rule_revision(context, self.codec)
        if action_delta(revised, context.bounded_action) > REVISION_TOLERANCE:
            return AuditOutcome("revise", revised, f"rule auditor revised for risk: {', '.join(risks)}")
        return AuditOutcome("approve", context.bounded_action, "rule auditor approved the bounded action")


class ApproveOnlyAuditor:
    """Approves every audited step."""

    kind = "approve-only"

    def audit(self, context: StepContext, site: CallSite) -> AuditOutcome:
        return AuditOutcome("approve", context.bounded_action, "approve-only auditor")


class LLMAuditor:
    """The model's verdict from the fixed auditor prompt; a revision is sanitised."""

    kind = "llm"

    def __init__(
        self,
        client: StructuredLLM,
        codec: LeverCodec,
        prompts: GovernancePrompts | None = None,
        levers: Levers | None = None,
    ) -> None:
        self.client = client
        self.codec = codec
        self.prompts = prompts  # the market's text (None: the default task's)
        self.output_model = output_models(levers)[1]

    def audit(self, context: StepContext, site: CallSite) -> AuditOutcome:
        messages = auditor_messages(context.to_prompt(self.codec), self.prompts)
        reply = self.client.request(messages, self.output_model, site)
        verdict, events = validate_audit(reply.output, self.codec)  # type: ignore[arg-type]
        llm = {**reply.meta, "clipped": [e.to_log() for e in events]}
        final = verdict.final_action if verdict.decision == "revise" else context.bounded_action
        return AuditOutcome(verdict.decision, final, verdict.reason, llm)
