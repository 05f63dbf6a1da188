"""The Planner/Auditor scheduler (docs/planner_auditor.md#scheduler), identical for every planner and auditor.

Per step: the proposed action is clipped to the plan's bounds and sanitised (ā); the audit-side
jitter κ = |ā - a_prev|_1 (float32); hard triggers H (violation, gap, slippage, read from the
float32 observation) and the soft trigger S (κ above the jitter threshold), all compared at
float32 precision, decide whether the Auditor is called. Hard-triggered audits bypass the budget and the cooldown but still count as used;
soft ones need audits used < B and, when the cooldown c > 0, step - last audited step > c.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from ..tasks.governance_view import LeverCodec
from .schemas import Plan

HARD_REASONS = ("violation", "gap", "slippage")
SKIP_BUDGET = "budget"
SKIP_COOLDOWN = "cooldown"

Action = tuple[float, float, float]

# Python floats rounded to float32 by struct packing (the market's float32 scalar arithmetic).
_F1 = struct.Struct("f")
_F3 = struct.Struct("3f")


def l1_f32(a: Action, b: Action) -> float:
    """|a - b|_1 of float32 actions in float32, summed left to right (numpy's order).

    The same operations as the solar market's action jitter, so κ and the action delta equal
    the env's jitter to the last bit.
    """
    d0, d1, d2 = _F3.unpack(_F3.pack(abs(a[0] - b[0]), abs(a[1] - b[1]), abs(a[2] - b[2])))
    (partial,) = _F1.unpack(_F1.pack(d0 + d1))
    return _F1.unpack(_F1.pack(partial + d2))[0]


def audit_budget(max_audits: int, target_rate: float, episode_steps: int) -> int:
    """B = clip(min(max audits, max(round(target rate · steps), 1)), 1, steps).

    ``round`` is numpy's (half to even), as in the original release.
    """
    target = int(np.round(float(target_rate) * float(episode_steps)))
    return int(np.clip(min(int(max_audits), max(target, 1)), 1, episode_steps))


def bound_action(proposed: Action, plan: Plan, codec: LeverCodec) -> Action:
    """ā: each component clipped to the plan's bounds, kept float32, then sanitised.

    The clipped values are rounded to float32 before sanitising, as the original release
    did with its float32 arrays (this decides the α + ℓ scaling to the last bit).
    """
    clipped = [float(np.float32(min(max(x, lo), hi))) for x, (lo, hi) in zip(proposed, plan.bounds, strict=True)]
    return codec.sanitize(*clipped)


def kappa(bounded: Action, previous: Action) -> float:
    """κ = |ā - a_prev|_1 of the float32 actions, summed in float32, returned widened."""
    return float(l1_f32(bounded, previous))


def soft_trigger(kappa_l1: float, plan: Plan) -> bool:
    """S = κ > τκ, compared at float32 precision like the hard triggers."""
    return bool(np.float32(kappa_l1) > np.float32(plan.jitter_threshold))


def action_delta(final: Action, proposed: Action) -> float:
    """|final - proposed|_1 in float32 (docs/reproducing.md#floating-point-rules), returned as a Python float."""
    return float(l1_f32(final, proposed))


def hard_reasons(violation_rate: float, supply_gap: float, static_slippage: float, plan: Plan) -> list[str]:
    """The hard triggers that hold: ν > τν, gap < τΔ, σ > τσ (in that order).

    The signals are float32 observation fields and are compared with the thresholds at
    float32 precision, as the original release's float32 arrays do under numpy 2. This
    matters on ties: ν = 5/50 read as float32(0.1) does not exceed a threshold of 0.1
    (in float64 it would, by 1.5e-9).
    """
    f32 = np.float32
    reasons = []
    if f32(violation_rate) > f32(plan.violation_threshold):
        reasons.append("violation")
    if f32(supply_gap) < f32(plan.gap_threshold):
        reasons.append("gap")
    if f32(static_slippage) > f32(plan.slippage_threshold):
        reasons.append("slippage")
    return reasons


@dataclass(frozen=True)
class Decision:
    """The scheduler's answer for one step."""

    audited: bool
    skip_reason: str | None  # None, "budget" or "cooldown" (only for a soft-only trigger)
    audits_used: int  # after this step


class AuditScheduler:
    """Budget and cooldown state of one episode.

    Parameters
    ----------
    budget : int
        B, the episode's audit budget (≥ 1).
    cooldown_steps : int
        c; 0 disables the cooldown.
    """

    def __init__(self, budget: int, cooldown_steps: int) -> None:
        if budget < 1:
            raise ValueError(f"audit budget must be at least 1, got {budget}")
        if cooldown_steps < 0:
            raise ValueError(f"cooldown must be non-negative, got {cooldown_steps}")
        self.budget = int(budget)
        self.cooldown_steps = int(cooldown_steps)
        self.audits_used = 0
        self.last_audited_step: int | None = None

    def step(self, step: int, hard: bool, soft: bool) -> Decision:
        """Decide whether ``step`` is audited, and record the audit if so."""
        if not (hard or soft):
            return Decision(False, None, self.audits_used)
        if not hard:
            if self.audits_used >= self.budget:
                return Decision(False, SKIP_BUDGET, self.audits_used)
            if (
                self.cooldown_steps > 0
                and self.last_audited_step is not None
                and step - self.last_audited_step <= self.cooldown_steps
            ):
                return Decision(False, SKIP_COOLDOWN, self.audits_used)
        self.audits_used += 1
        self.last_audited_step = step
        return Decision(True, None, self.audits_used)
