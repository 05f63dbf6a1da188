"""Planners: called once per episode, they return the bounds and audit policy in force.

- ``rule`` (docs/planner_auditor.md#rule-planner): "rule_conservative" when the episode's
  max ν > 0.01, min gap < -0.10 or mean σ > 0.75 (statistics of the hourly table over the
  episode's 24 hours), else "rule_balanced".
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
from ..market.actions import ActionCodec
from .prompts import planner_messages
from .schemas import ActionBounds, AuditPolicy, Bounds, Plan, PlannerOutput, validate_plan

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
    """What a planner knows before the episode: its hours' statistics and the rules.

    Statistics are over the episode's hours of the hourly table; ``supply_gap`` is the
    observation's (G_v - Q) / max(Q, 1e-6) (unclipped, float64). Energies in MWh.
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

    def to_prompt(self, codec: ActionCodec) -> dict[str, Any]:
        # Run-constant keys first: they form a prefix shared with the previous planner call.
        return {
            "benchmark_ranges": benchmark_ranges(codec),
            "episode_steps": self.episode_steps,
            "physics_penalty_in_reward": self.physics_penalty,
            "start_hour_of_day": self.start_hour % 24,
            "episode_statistics": {name: _sig(value) for name, value in self.statistics.items()},
        }


def benchmark_ranges(codec: ActionCodec) -> dict[str, Any]:
    """The action ranges and the allocation cap, as both prompts show them."""
    return {
        "reward_ratio": [codec.lo[0], codec.hi[0]],
        "liquidity_ratio": [codec.lo[1], codec.hi[1]],
        "burn_rate": [codec.lo[2], codec.hi[2]],
        "max_total_allocation": codec.max_total_allocation,
    }


def episode_context(env: Any, start_hour: int) -> EpisodeContext:
    """Statistics of the episode starting at ``start_hour`` from ``env``'s hourly table."""
    table, steps = env.table, env.episode_steps
    hours = np.minimum(np.arange(start_hour, start_hour + steps), table.hours - 1)
    violation = np.ascontiguousarray(table.raw_violation_rate[hours])
    gap = np.ascontiguousarray(env.market_hours.supply_gap[hours])
    slippage = np.ascontiguousarray(table.static_slippage[hours])
    verified = np.ascontiguousarray(table.verified_mwh[hours])
    demand = np.ascontiguousarray(table.demand_mwh[hours])
    stats = {
        "max_violation_rate": float(np.max(violation)),
        "mean_violation_rate": float(np.mean(violation)),
        "min_supply_gap": float(np.min(gap)),
        "mean_supply_gap": float(np.mean(gap)),
        "mean_static_slippage": float(np.mean(slippage)),
        "max_static_slippage": float(np.max(slippage)),
        "mean_verified_supply_MWh": float(np.mean(verified)),
        "max_verified_supply_MWh": float(np.max(verified)),
        "mean_demand_MWh": float(np.mean(demand)),
        "hours_with_supply_shortfall": float(np.sum(gap < 0)),
    }
    return EpisodeContext(
        start_hour=int(start_hour),
        episode_steps=int(steps),
        physics_penalty=not env.config.no_physics_penalty,
        max_violation_rate=stats["max_violation_rate"],
        min_supply_gap=stats["min_supply_gap"],
        mean_static_slippage=stats["mean_static_slippage"],
        statistics=stats,
        hourly_signals=tuple(np.clip(x.astype(np.float32), -10.0, 10.0) for x in (violation, gap, slippage)),
    )


@dataclass(frozen=True)
class PlanOutcome:
    plan: Plan
    llm: dict[str, Any] | None = None  # call metadata and clip events (LLM planner only)


class Planner(Protocol):
    kind: str

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome: ...


def _bounds(low: float, high: float) -> Bounds:
    return Bounds(low=low, high=high)


class RulePlanner:
    """The rule planner (docs/planner_auditor.md#rule-planner)."""

    kind = "rule"

    def __init__(self, codec: ActionCodec) -> None:
        self.codec = codec

    def output(self, context: EpisodeContext) -> PlannerOutput:
        lo, hi = self.codec.lo, self.codec.hi
        risky = (
            context.max_violation_rate > RISK_MAX_VIOLATION
            or context.min_supply_gap < RISK_MIN_GAP
            or context.mean_static_slippage > RISK_MEAN_SLIPPAGE
        )
        if risky:
            return PlannerOutput(
                governance_mode="rule_conservative",
                action_bounds=ActionBounds(
                    reward_ratio=_bounds(lo[0], min(0.45, hi[0])),
                    liquidity_ratio=_bounds(max(0.35, lo[1]), hi[1]),
                    burn_rate=_bounds(0.02, min(0.18, hi[2])),
                ),
                audit_policy=CONSERVATIVE_POLICY,
                rationale="Episode risk signals (violations, shortfall or slippage) call for conservative bounds.",
            )
        return PlannerOutput(
            governance_mode="rule_balanced",
            action_bounds=ActionBounds(
                reward_ratio=_bounds(lo[0], hi[0]),
                liquidity_ratio=_bounds(lo[1], hi[1]),
                burn_rate=_bounds(lo[2], hi[2]),
            ),
            audit_policy=BALANCED_POLICY,
            rationale="Low episode risk: full action ranges with balanced audit thresholds.",
        )

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome:
        plan, _ = validate_plan(self.output(context), self.codec, context.episode_steps)
        return PlanOutcome(plan)


class DefaultPlanner:
    """Full action ranges and the balanced audit policy, every episode."""

    kind = "default"

    def __init__(self, codec: ActionCodec) -> None:
        self.codec = codec

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome:
        lo, hi = self.codec.lo, self.codec.hi
        output = PlannerOutput(
            governance_mode="default_full_bounds",
            action_bounds=ActionBounds(
                reward_ratio=_bounds(lo[0], hi[0]),
                liquidity_ratio=_bounds(lo[1], hi[1]),
                burn_rate=_bounds(lo[2], hi[2]),
            ),
            audit_policy=BALANCED_POLICY,
            rationale="Default plan: full action ranges, balanced audit thresholds.",
        )
        plan, _ = validate_plan(output, self.codec, context.episode_steps)
        return PlanOutcome(plan)


class LLMPlanner:
    """The model's plan from the fixed planner prompt; validated and clipped."""

    kind = "llm"

    def __init__(self, client: StructuredLLM, codec: ActionCodec) -> None:
        self.client = client
        self.codec = codec

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome:
        reply = self.client.request(planner_messages(context.to_prompt(self.codec)), PlannerOutput, site)
        plan, events = validate_plan(reply.output, self.codec, context.episode_steps)  # type: ignore[arg-type]
        return PlanOutcome(plan, {**reply.meta, "clipped": [e.to_log() for e in events]})
