"""Controls and ablations of the Planner/Auditor layer (docs/governance.md#controls).

Auditor controls (selected with ``--auditor`` like ``rule`` and ``approve-only``):

- ``always-audit``: every step is audited, with the rule auditor's revision.
- ``random``: a seeded, uniformly random set of steps is audited, as many per episode as the
  reference auditor audited in that episode (``random_audit_counts``), or round(rate · steps)
  (``random_audit_rate``), or else the plan's budget B, with the rule auditor's revision.
  Against ``rule`` it isolates the selectivity of the triggers.
- ``oracle``: the scheduler's steps, and on each the action of the benchmark's 125-point grid
  (or ā) that minimises the counterfactual cost (the market's view's; the solar market's V + A)
  with a reward loss against ā of at most ``oracle_reward_loss``. With an unbounded loss, on the
  solar market, its cost is the least any action can reach, as cost only grows with α + ℓ.

Scheduler ablations (:class:`SchedulerControls`): which triggers may call an audit (all, hard
only, soft only, one hard trigger alone) and overrides of the plan's budget and cooldown.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..llm.errors import CallSite
from ..tasks.governance_view import GovernanceView, LeverCodec
from .auditor import REVISION_TOLERANCE, AuditOutcome, RuleAuditor, StepContext
from .counterfactual import executed_form
from .errors import GovernanceConfigError
from .scheduler import HARD_REASONS, Decision, action_delta
from .view import default_view

#: Trigger sets of the ablations: every trigger, the hard ones, the soft one, or one hard trigger.
TRIGGER_SETS = ("all", "hard", "soft", *HARD_REASONS)
#: Default reward-loss bound of the oracle per audited step (reward units; docs/governance.md#controls).
DEFAULT_ORACLE_REWARD_LOSS = 0.05
ORACLE_GRID_LEVELS = 5


@dataclass(frozen=True)
class SchedulerControls:
    """Trigger ablation and budget/cooldown overrides (the defaults change nothing).

    Parameters
    ----------
    triggers : {"all", "hard", "soft", "violation", "gap", "slippage"}
        The triggers that may call an audit.
    max_audits : int, optional
        Replaces the plan's ``max_audits_per_episode`` (the budget B is then computed as usual).
    cooldown_steps : int, optional
        Replaces the plan's cooldown c.
    """

    triggers: str = "all"
    max_audits: int | None = None
    cooldown_steps: int | None = None

    def __post_init__(self) -> None:
        if self.triggers not in TRIGGER_SETS:
            raise GovernanceConfigError(
                f"unknown trigger set {self.triggers!r} (choose from {', '.join(TRIGGER_SETS)})"
            )
        if self.max_audits is not None and self.max_audits < 1:
            raise GovernanceConfigError(f"max audits must be at least 1, got {self.max_audits}")
        if self.cooldown_steps is not None and self.cooldown_steps < 0:
            raise GovernanceConfigError(f"cooldown must be non-negative, got {self.cooldown_steps}")

    @property
    def is_default(self) -> bool:
        return self == SchedulerControls()

    def triggers_used(self, reasons: list[str], soft: bool) -> tuple[list[str], bool]:
        """The hard reasons and soft trigger the ablation keeps."""
        if self.triggers == "all":
            return reasons, soft
        if self.triggers == "hard":
            return reasons, False
        if self.triggers == "soft":
            return [], soft
        return [r for r in reasons if r == self.triggers], False

    def describe(self) -> dict[str, object]:
        return {"triggers": self.triggers, "max_audits": self.max_audits, "cooldown_steps": self.cooldown_steps}


class FixedScheduler:
    """Audits exactly the steps in ``selected``, whatever the triggers (same interface as
    :class:`~solarchain_eval.governance.scheduler.AuditScheduler`)."""

    def __init__(self, selected: frozenset[int]) -> None:
        self.selected = selected
        self.audits_used = 0

    def step(self, step: int, hard: bool, soft: bool) -> Decision:
        if step not in self.selected:
            return Decision(False, None, self.audits_used)
        self.audits_used += 1
        return Decision(True, None, self.audits_used)


class AlwaysAuditAuditor(RuleAuditor):
    """Audits every step; revises like the rule auditor."""

    kind = "always-audit"

    def select_steps(self, *, steps: int, budget: int, run_seed: int, episode: int, policy: str) -> frozenset[int]:
        return frozenset(range(steps))


def random_audit_count(rate: float | None, budget: int, steps: int) -> int:
    """Steps to audit per episode: round(rate · steps) (numpy's half to even), else the budget B."""
    if rate is None:
        return int(budget)
    return int(np.clip(np.round(float(rate) * steps), 0, steps))


class RandomAuditor(RuleAuditor):
    """Audits a seeded random set of steps per episode; revises like the rule auditor.

    Parameters
    ----------
    codec : LeverCodec
    rates : float or mapping of policy name -> float, optional
        The audit rate to match (a mapping gives each policy its own, e.g. the reference
        auditor's measured rate); None or a policy absent from the mapping: the plan's budget B.
    seed : int
        Seed of the selection; the stream of an episode is keyed by (seed, run seed, episode, policy).
    counts : mapping of (policy, run seed, episode) -> int, optional
        Audits per episode to match exactly (the reference's); wins over ``rates`` where given.
    """

    kind = "random"

    def __init__(
        self,
        codec: LeverCodec,
        rates: float | Mapping[str, float] | None = None,
        seed: int = 0,
        counts: Mapping[tuple[str, int, int], int] | None = None,
    ) -> None:
        super().__init__(codec)
        self.rates = rates
        self.seed = int(seed)
        self.counts = counts or {}

    def rate_for(self, policy: str) -> float | None:
        if isinstance(self.rates, Mapping):
            return self.rates.get(policy)
        return self.rates

    def select_steps(self, *, steps: int, budget: int, run_seed: int, episode: int, policy: str) -> frozenset[int]:
        matched = self.counts.get((policy, int(run_seed), int(episode)))
        count = int(matched) if matched is not None else random_audit_count(self.rate_for(policy), budget, steps)
        rng = np.random.default_rng([self.seed, int(run_seed), int(episode), zlib.crc32(policy.encode())])
        return frozenset(int(i) for i in rng.choice(steps, size=count, replace=False))


class OracleAuditor:
    """The least-cost action with bounded reward loss, from the counterfactual evaluator.

    Parameters
    ----------
    codec : LeverCodec
    reward_loss : float
        Largest admissible reward(ā) - reward(a) per audited step (``inf``: unbounded).
    view : GovernanceView, optional
        The market's view, which reads an outcome's cost and reward (None: the default task's).
    """

    kind = "oracle"

    def __init__(
        self, codec: LeverCodec, reward_loss: float = DEFAULT_ORACLE_REWARD_LOSS, view: GovernanceView | None = None
    ) -> None:
        if not (reward_loss >= 0):
            raise GovernanceConfigError(f"the oracle's reward-loss bound must be non-negative, got {reward_loss}")
        self.codec = codec
        self.view = view if view is not None else default_view()
        self.reward_loss = float(reward_loss)
        self.grid = codec.discrete_table(ORACLE_GRID_LEVELS)
        # Each candidate with the form the env executes, computed once (the evaluator would
        # compute the same decode(encode(a)) at every audited step).
        self._executed = [executed_form(a, codec) for a in self.grid]

    def best(self, context: StepContext) -> tuple[tuple[float, float, float], float, float]:
        """(action, cost, reward): ā unless an admissible grid action costs strictly less; among
        those, the least cost, then the highest reward, then the first in grid order."""
        evaluate = context.counterfactual
        if evaluate is None:
            raise GovernanceConfigError("the oracle auditor needs the counterfactual evaluator (a governed env step)")
        cost_of, reward_of = self.view.outcome_cost, self.view.outcome_reward
        base = evaluate(context.bounded_action)
        base_reward = reward_of(base)
        floor = base_reward - self.reward_loss if math.isfinite(self.reward_loss) else -math.inf
        best, best_cost, best_reward = context.bounded_action, cost_of(base), base_reward
        evaluate_executed = getattr(evaluate, "executed", None)
        for action, executed in zip(self.grid, self._executed, strict=True):
            outcome = evaluate_executed(executed) if evaluate_executed is not None else evaluate(action)
            reward = reward_of(outcome)
            if reward < floor:
                continue
            cost = cost_of(outcome)
            improves = cost < best_cost or (best is not context.bounded_action and cost == best_cost)
            if improves and (cost < best_cost or reward > best_reward):
                best, best_cost, best_reward = action, cost, reward
        return best, best_cost, best_reward

    def audit(self, context: StepContext, site: CallSite) -> AuditOutcome:
        action, cost, reward = self.best(context)
        if action_delta(action, context.bounded_action) > REVISION_TOLERANCE:
            return AuditOutcome("revise", action, f"oracle: least cost {cost:.6g} at reward {reward:.6g}")
        return AuditOutcome("approve", context.bounded_action, "oracle: no admissible action costs less")
