"""Planners: called once per episode, they return the bounds and audit policy in force.

- ``rule`` (docs/planner_auditor.md#rule-planner): "rule_conservative" when the episode's
  max ν > 0.01, min gap < -0.10 or mean σ > 0.75 (its risk signals over the episode's hours, as
  the market's governance view reads them: for the solar market, from the hourly table), else
  "rule_balanced".
- ``default``: the full action ranges and the balanced thresholds (isolates the Auditor).
- ``llm``: the model's structured plan, validated and clipped (each clip logged).

Every planner's output goes through the same validation
(:func:`~solarchain_eval.governance.schemas.validate_plan`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ..llm.client import StructuredLLM
from ..llm.errors import CallSite
from ..tasks.governance_view import EpisodeRisk, GovernancePrompts, GovernanceView, LeverCodec
from .prompts import planner_messages
from .schemas import (
    ACTION_FIELDS,
    AuditPolicy,
    Levers,
    Plan,
    PlannerOutput,
    action_bounds,
    output_models,
    validate_plan,
)
from .view import resolve_view

PLANNER_KINDS = ("rule", "llm", "default", "calibrated-rule")

# Rule-planner constants (docs/planner_auditor.md#rule-planner).
RISK_MAX_VIOLATION = 0.01
RISK_MIN_GAP = -0.10
RISK_MEAN_SLIPPAGE = 0.75
BALANCED_POLICY = AuditPolicy(
    violation_threshold=0.01,
    gap_threshold=-0.10,
    jitter_threshold=0.25,
    slippage_threshold=0.75,
    max_audits_per_episode=6,
    target_audit_rate=0.25,
    cooldown_steps=2,
)
CONSERVATIVE_POLICY = AuditPolicy(
    violation_threshold=0.005,
    gap_threshold=-0.05,
    jitter_threshold=0.18,
    slippage_threshold=0.60,
    max_audits_per_episode=6,
    target_audit_rate=0.25,
    cooldown_steps=2,
)


def _sig(value: float) -> float:
    """Six significant digits: readable prompts, still deterministic."""
    return float(f"{value:.6g}")


@dataclass(frozen=True)
class EpisodeContext:
    """What a planner knows before the episode: its risk signals' statistics and the rules.

    Built from the market's :class:`~solarchain_eval.tasks.governance_view.EpisodeRisk`
    (:meth:`from_risk`): the three headline statistics are the maximum violation rate, the
    minimum supply gap and the mean slippage over the episode's steps (float64); ``statistics``
    are the market's named statistics the LLM planner's prompt shows.
    """

    start_hour: int
    episode_steps: int
    physics_penalty: bool
    max_violation_rate: float
    min_supply_gap: float
    mean_static_slippage: float
    statistics: dict[str, float]
    #: Per-step trigger signals (ν, gap, σ) as the observation shows them (float32, clipped to
    #: ±10): what the calibrated planner takes its quantiles of; never shown to a model.
    hourly_signals: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, compare=False, repr=False)

    @classmethod
    def from_risk(cls, risk: EpisodeRisk) -> EpisodeContext:
        violation, gap, slippage = (np.asarray(x) for x in risk.signals)
        return cls(
            start_hour=int(risk.start_hour),
            episode_steps=int(risk.episode_steps),
            physics_penalty=bool(risk.penalty_in_reward),
            max_violation_rate=float(np.max(violation)),
            min_supply_gap=float(np.min(gap)),
            mean_static_slippage=float(np.mean(slippage)),
            statistics=dict(risk.statistics),
            hourly_signals=tuple(np.clip(x.astype(np.float32), -10.0, 10.0) for x in (violation, gap, slippage)),
        )

    def to_prompt(self, codec: LeverCodec, lever_names: tuple[str, ...] = ACTION_FIELDS) -> dict[str, Any]:
        # Run-constant keys first: they form a prefix shared with the previous planner call.
        return {
            "benchmark_ranges": benchmark_ranges(codec, lever_names),
            "episode_steps": self.episode_steps,
            "physics_penalty_in_reward": self.physics_penalty,
            "start_hour_of_day": self.start_hour % 24,
            "episode_statistics": {name: _sig(value) for name, value in self.statistics.items()},
        }


def benchmark_ranges(codec: LeverCodec, lever_names: tuple[str, ...] = ACTION_FIELDS) -> dict[str, Any]:
    """The action ranges by lever name and the allocation cap, as the prompts show them."""
    return {
        **{name: [low, high] for name, low, high in zip(lever_names, codec.lo, codec.hi, strict=True)},
        "max_total_allocation": codec.max_total_allocation,
    }


def episode_context(env: Any, start_hour: int, view: GovernanceView | None = None) -> EpisodeContext:
    """The context of the episode ``env`` starts at ``start_hour``, from the market's governance view.

    ``view`` None: the default task's view of ``env.config`` (the solar market).
    """
    view = view if view is not None else resolve_view(env.config)
    return EpisodeContext.from_risk(view.episode_risk(env, int(start_hour)))


@dataclass(frozen=True)
class PlanOutcome:
    plan: Plan
    llm: dict[str, Any] | None = None  # call metadata and clip events (LLM planner only)


class Planner(Protocol):
    kind: str

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome: ...


class RulePlanner:
    """The rule planner (docs/planner_auditor.md#rule-planner).

    ``levers`` (name, description) of the market's levers names the output's bounds (None: the
    solar market's).
    """

    kind = "rule"

    def __init__(self, codec: LeverCodec, levers: Levers | None = None) -> None:
        self.codec = codec
        self.output_model = output_models(levers)[0]

    def output(self, context: EpisodeContext) -> PlannerOutput:
        lo, hi = self.codec.lo, self.codec.hi
        risky = (
            context.max_violation_rate > RISK_MAX_VIOLATION
            or context.min_supply_gap < RISK_MIN_GAP
            or context.mean_static_slippage > RISK_MEAN_SLIPPAGE
        )
        if risky:
            return self.output_model(
                governance_mode="rule_conservative",
                action_bounds=action_bounds(
                    self.output_model,
                    [(lo[0], min(0.45, hi[0])), (max(0.35, lo[1]), hi[1]), (0.02, min(0.18, hi[2]))],
                ),
                audit_policy=CONSERVATIVE_POLICY,
                rationale="Episode risk signals (violations, shortfall or slippage) call for conservative bounds.",
            )
        return self.output_model(
            governance_mode="rule_balanced",
            action_bounds=action_bounds(self.output_model, list(zip(lo, hi, strict=True))),
            audit_policy=BALANCED_POLICY,
            rationale="Low episode risk: full action ranges with balanced audit thresholds.",
        )

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome:
        plan, _ = validate_plan(self.output(context), self.codec, context.episode_steps)
        return PlanOutcome(plan)


class DefaultPlanner:
    """Full action ranges and the balanced audit policy, every episode."""

    kind = "default"

    def __init__(self, codec: LeverCodec, levers: Levers | None = None) -> None:
        self.codec = codec
        self.output_model = output_models(levers)[0]

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome:
        output = self.output_model(
            governance_mode="default_full_bounds",
            action_bounds=action_bounds(self.output_model, list(zip(self.codec.lo, self.codec.hi, strict=True))),
            audit_policy=BALANCED_POLICY,
            rationale="Default plan: full action ranges, balanced audit thresholds.",
        )
        plan, _ = validate_plan(output, self.codec, context.episode_steps)
        return PlanOutcome(plan)


class LLMPlanner:
    """The model's plan from the fixed planner prompt; validated and clipped."""

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
        self.output_model = output_models(levers)[0]
        self.lever_names = tuple(self.output_model.model_fields["action_bounds"].annotation.model_fields)  # type: ignore[union-attr]

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome:
        messages = planner_messages(context.to_prompt(self.codec, self.lever_names), self.prompts)
        reply = self.client.request(messages, self.output_model, site)
        plan, events = validate_plan(reply.output, self.codec, context.episode_steps)  # type: ignore[arg-type]
        return PlanOutcome(plan, {**reply.meta, "clipped": [e.to_log() for e in events]})
