"""Per-episode agentic metrics (docs/metrics.md#agentic-metrics) from an episode's step log rows.

The columns added to ``metrics.csv`` for the agentic settings, in this order:
:data:`~solarchain_eval.records_schema.AGENTIC_METRIC_NAMES` (units and meanings in
:mod:`solarchain_eval.records_schema`). Trigger rates are the fraction of the episode's steps
whose condition held, whether or not the step was audited (``soft`` = the jitter condition
κ > τκ; ``not_triggered_rate`` is the fraction with neither a hard nor a soft trigger).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..records_schema import AGENTIC_METRIC_NAMES as AGENTIC_METRIC_NAMES  # the column order, re-exported
from .schemas import Plan

MODIFICATION_TOLERANCE = 1e-6  # |final - proposed|_1 above which a step counts as modified


def episode_agentic_metrics(
    rows: Sequence[dict[str, Any]],
    *,
    plan: Plan,
    budget: int,
    steps: int,
    planner: str,
    auditor: str,
    planner_retries: int = 0,
) -> dict[str, Any]:
    """The episode's agentic metrics.

    Parameters
    ----------
    rows : sequence of dict
        The episode's step log rows (``agentic_logs.jsonl`` rows).
    plan : Plan
        The validated plan in force.
    budget : int
        B, the episode's audit budget.
    steps : int
        Episode length (the denominator of every per-step rate, 24 in the paper).
    planner, auditor : str
        Component kinds, recorded as columns.
    planner_retries : int
        Failed attempts the planner's LLM call recovered from.

    Notes
    -----
    ``plan_validity_rate`` is the fraction of plans that passed schema validation; an invalid
    plan fails the run, so a finished episode always has 1.0. ``llm_retry_count`` counts
    failed attempts (transport errors, 429/5xx answers) that a retry recovered; unrecovered
    failures fail the run. ``mean_action_delta`` is the float64 sum of the float32 per-step
    deltas, in step order, divided by ``steps``.
    """
    n = float(steps)
    audits = sum(1 for r in rows if r["audited"])
    revisions = sum(1 for r in rows if r["decision"] == "revise")
    delta_sum = 0.0
    for r in rows:
        delta_sum += r["action_delta"]
    modified = sum(1 for r in rows if r["action_delta"] > MODIFICATION_TOLERANCE)
    retries = planner_retries + sum(int(r["llm"]["retries"]) for r in rows if r["llm"] is not None)

    def rate(condition) -> float:
        return sum(1 for r in rows if condition(r)) / n

    return {
        "plan_validity_rate": 1.0,
        "audit_rate": audits / n,
        "revision_rate": revisions / max(audits, 1),
        "modification_rate": modified / n,
        "mean_action_delta": delta_sum / n,
        "llm_retry_count": retries,
        "hard_trigger_rate": rate(lambda r: r["hard_trigger"]),
        "soft_trigger_rate": rate(lambda r: r["soft_trigger"]),
        "not_triggered_rate": rate(lambda r: not (r["hard_trigger"] or r["soft_trigger"])),
        "physics_trigger_rate": rate(lambda r: "violation" in r["hard_reasons"]),
        "gap_trigger_rate": rate(lambda r: "gap" in r["hard_reasons"]),
        "slippage_trigger_rate": rate(lambda r: "slippage" in r["hard_reasons"]),
        "plan_violation_threshold": plan.violation_threshold,
        "plan_gap_threshold": plan.gap_threshold,
        "plan_jitter_threshold": plan.jitter_threshold,
        "plan_slippage_threshold": plan.slippage_threshold,
        "plan_audit_budget": int(budget),
        "governance_mode": plan.governance_mode,
        "planner": planner,
        "auditor": auditor,
    }
