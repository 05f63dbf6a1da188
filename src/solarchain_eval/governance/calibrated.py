"""The calibrated rule planner (docs/governance.md#calibrated-rule-planner).

The paper's rule planner fixes τσ at 0.60/0.75, below the published data's static slippage, so
its slippage trigger fires on every step and the audit rate is 1. The calibrated planner keeps
the rule planner's bounds but sets the three hard thresholds at quantiles of the episode's own
signals (the observation's ν, gap and σ of its hours, known before the episode): lowering them
one signal value at a time, it stops at the thresholds whose hard-trigger rate is closest to a
target audit rate r (ties: the lower rate). The soft trigger is switched off (τκ = 3 exceeds any κ ≤ 1.55), so the audit rate is
exactly the calibrated hard-trigger rate, whatever the policy does.
"""

from __future__ import annotations

import numpy as np

from ..llm.errors import CallSite
from ..tasks.governance_view import LeverCodec
from .errors import GovernanceConfigError
from .planner import EpisodeContext, PlanOutcome, RulePlanner
from .schemas import (
    GAP_THRESHOLD_RANGE,
    JITTER_THRESHOLD_RANGE,
    SLIPPAGE_THRESHOLD_RANGE,
    VIOLATION_THRESHOLD_RANGE,
    AuditPolicy,
    Levers,
    validate_plan,
)

DEFAULT_TARGET_AUDIT_RATE = 0.25
_F32 = np.float32


def hard_trigger_mask(
    signals: tuple[np.ndarray, np.ndarray, np.ndarray], thresholds: tuple[float, float, float]
) -> np.ndarray:
    """Steps whose hard trigger fires: ν > τν or gap < τΔ or σ > τσ, compared in float32."""
    violation, gap, slippage = signals
    tv, tg, ts = (_F32(t) for t in thresholds)
    return (violation > tv) | (gap < tg) | (slippage > ts)


def _candidates(values: np.ndarray, low: float, high: float, upper_tail: bool) -> list[float]:
    """Thresholds in the order that lets more steps fire: from the range end where none fires
    through every distinct signal value to the other end of the range."""
    inside = [float(v) for v in np.unique(values) if low <= float(v) <= high]
    ordered = sorted({low, high, *inside}, reverse=upper_tail)
    return ordered


def calibrated_thresholds(
    signals: tuple[np.ndarray, np.ndarray, np.ndarray], target_rate: float
) -> tuple[tuple[float, float, float], float]:
    """(τν, τΔ, τσ) and the hard-trigger rate they give over the episode's steps.

    Greedy path from "nothing fires" (each threshold at the end of its range): at each move one
    threshold goes to its next candidate value (the one adding the fewest newly triggered steps;
    ties in the order ν, gap, σ). Of the states on the path, the one whose rate is closest to
    ``target_rate`` wins, the lower rate on a tie.
    """
    ranges = (VIOLATION_THRESHOLD_RANGE, GAP_THRESHOLD_RANGE, SLIPPAGE_THRESHOLD_RANGE)
    upper = (True, False, True)  # ν and σ fire above their threshold, the gap below it
    lists = [
        _candidates(np.asarray(x, dtype=_F32), lo, hi, tail)
        for x, (lo, hi), tail in zip(signals, ranges, upper, strict=True)
    ]
    index = [0, 0, 0]

    def state() -> tuple[float, float, float]:
        return (lists[0][index[0]], lists[1][index[1]], lists[2][index[2]])

    def rate_of(thresholds: tuple[float, float, float]) -> float:
        return float(hard_trigger_mask(signals, thresholds).mean())

    current = state()
    best = (current, rate_of(current))
    while True:
        moves = []
        for i in range(3):
            if index[i] + 1 < len(lists[i]):
                index[i] += 1
                moves.append((rate_of(state()), i))
                index[i] -= 1
        if not moves:
            break
        rate, i = min(moves)
        index[i] += 1
        if abs(rate - target_rate) < abs(best[1] - target_rate) - 1e-12:
            best = (state(), rate)
        if rate >= target_rate:
            break
    return best


class CalibratedRulePlanner(RulePlanner):
    """Rule-planner bounds, hard thresholds calibrated to a target audit rate.

    Parameters
    ----------
    codec : LeverCodec
    target_rate : float
        The audit rate to reach, in (0, 1].
    """

    kind = "calibrated-rule"

    def __init__(
        self, codec: LeverCodec, target_rate: float = DEFAULT_TARGET_AUDIT_RATE, levers: Levers | None = None
    ) -> None:
        super().__init__(codec, levers)
        if not 0.0 < target_rate <= 1.0:
            raise GovernanceConfigError(
                f"the calibrated planner's target audit rate must be in (0, 1], got {target_rate}"
            )
        self.target_rate = float(target_rate)

    def plan(self, context: EpisodeContext, site: CallSite) -> PlanOutcome:
        if context.hourly_signals is None:
            raise GovernanceConfigError("the calibrated planner needs the episode's hourly signals (episode_context)")
        rule = self.output(context)
        (tv, tg, ts), rate = calibrated_thresholds(context.hourly_signals, self.target_rate)
        steps = context.episode_steps
        budget = max(int(np.round(self.target_rate * steps)), 1)
        output = self.output_model(
            governance_mode=rule.governance_mode.replace("rule_", "calibrated_"),
            action_bounds=rule.action_bounds,
            audit_policy=AuditPolicy(
                violation_threshold=tv,
                gap_threshold=tg,
                jitter_threshold=JITTER_THRESHOLD_RANGE[1],
                slippage_threshold=ts,
                max_audits_per_episode=budget,
                target_audit_rate=self.target_rate,
                cooldown_steps=0,
            ),
            rationale=f"Thresholds at the episode's quantiles: hard-trigger rate {rate:.4f} for target {self.target_rate}.",
        )
        plan, _ = validate_plan(output, self.codec, steps)
        return PlanOutcome(plan)
