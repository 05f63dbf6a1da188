"""Paired-delta tables: removing the physics penalty, and adding the Planner/Auditor layer.

Deltas match rollouts on setting pair, policy, run seed and episode (and check the episode
seed agrees); mean ± sample std (ddof=1) over the matched pairs, as in the paper.
"""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from ....evaluation.settings import SETTING_AGENTIC, SETTING_MAIN
from ...loading import ReportData
from ...naming import (
    ABLATION_PAIRS,
    AGENTIC_BASE,
    AGENTIC_REWARD_LABELS,
    GOVERNANCE_LABELS,
    learned_order,
    paper_order,
    policy_label,
)
from ...options import ReportOptions
from ...statistics import paired_deltas
from ...table_model import Column, ReportTable, Skipped, basis_sentence, cell, cell_pm, text
from .common import agentic_rollouts, moments, pooled_revision_rate, size_fields, sizes_of

ABLATION_METRICS = (
    ("cumulative_reward", "Δ Reward", 2),
    ("physics_violation_rate", "Δ Physics Violation", 4),
    ("artificial_liquidity_MWh", "Δ Artificial Liquidity", 4),
    ("mean_slippage", "Δ Slippage", 4),
)
AGENTIC_METRICS = (
    ("cumulative_reward", "Δ Reward", 3),
    ("action_jitter", "Δ Action Jitter", 4),
    ("artificial_liquidity_MWh", "Δ Artificial Liquidity", 4),
    ("spatial_fairness_index", "Δ Spatial Fairness", 4),
)
DETAIL_METRICS = (
    "cumulative_reward",
    "action_jitter",
    "spatial_fairness_index",
    "artificial_liquidity_MWh",
    "mean_slippage",
)


def _delta_header(header: str) -> str:
    return header.replace("Δ", r"$\Delta$")


def _paired_rows(
    data: ReportData,
    pairs: Sequence[tuple[str, str, str]],
    columns: Sequence[str],
    order,
) -> tuple[list[dict], list[str]]:
    """One row per (label, policy) of matched deltas; notes on unmatched rollouts."""
    rows, notes = [], []
    metrics = data.metrics
    for label, base, treated in pairs:
        # Only policies evaluated in both settings are compared (baselines never get the LLM layer).
        both = set(metrics.loc[metrics["setting"] == base, "policy"]) & set(
            metrics.loc[metrics["setting"] == treated, "policy"]
        )
        deltas = paired_deltas(metrics[metrics["policy"].isin(both)], base, treated, columns)
        if deltas.unmatched:
            notes.append(
                f"{label}: {deltas.unmatched} rollout(s) of {base} / {treated} have no partner "
                "(same policy, run seed and episode) and are left out."
            )
        for policy in order(deltas.frame["policy"]):
            group = deltas.frame[deltas.frame["policy"] == policy]
            rows.append(
                {
                    "comparison": label,
                    "policy": policy_label(policy),
                    "_policy": policy,
                    **size_fields(group),
                    **moments(group, columns),
                }
            )
    return rows, notes


def physics_ablation_deltas(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """No-physics minus physics-penalised, for raw RL and for RL+LLM (learned policies)."""
    title = "Paired without-constraints deltas"
    pairs = [
        (GOVERNANCE_LABELS[base], base, treated)
        for base, treated in ABLATION_PAIRS.items()
        if {base, treated} <= set(data.settings)
    ]
    if not pairs:
        return Skipped(
            "physics_ablation_deltas",
            title,
            "needs a physics-penalised setting and its no-physics ablation (main + no_physics, or llm + llm_no_physics)",
        )
    names = [m for m, _, _ in ABLATION_METRICS]
    rows, notes = _paired_rows(data, pairs, names, learned_order)
    if not rows:
        return Skipped("physics_ablation_deltas", title, "no learned policy was evaluated in both settings of a pair")
    frame = pd.DataFrame(rows).drop(columns="_policy")
    columns = [Column("Governance", text("comparison"), align="l"), Column("Policy", text("policy"), align="l")]
    columns += [Column(h, cell_pm(n, d), latex=_delta_header(h)) for n, h, d in ABLATION_METRICS]
    return ReportTable(
        key="physics_ablation_deltas",
        label="tab:physics-ablation-deltas",
        title=title,
        caption=(
            "Paired without-constraints deltas (no-physics minus physics-penalised) with and without the LLM "
            "governance layer, mean ± sample std over pairs matched on policy, run seed and episode. Positive "
            "Δ reward indicates that removing the physics penalty increases scalar utility; positive Δ "
            "violation or artificial liquidity indicates increased safety risk."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "paired rollouts"),
        notes=notes,
    )


def agentic_effects(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """RL+LLM minus RL under the physics reward, with the audit and revision rates."""
    title = "Paired effects of the Planner/Auditor layer"
    if not {SETTING_MAIN, SETTING_AGENTIC} <= set(data.settings):
        return Skipped("agentic_effects", title, "needs the main setting and the agentic setting 'llm' (RL+LLM)")
    agentic, missing = agentic_rollouts(data, [SETTING_AGENTIC])
    if missing:
        return Skipped(
            "agentic_effects", title, f"metrics of setting 'llm' lack agentic column(s) {', '.join(missing)}"
        )
    names = [m for m, _, _ in AGENTIC_METRICS]
    rows, notes = _paired_rows(data, [("Main", SETTING_MAIN, SETTING_AGENTIC)], names, learned_order)
    if not rows:
        return Skipped("agentic_effects", title, "no learned policy was evaluated in both 'main' and 'llm'")
    for row in rows:
        group = agentic[agentic["policy"] == row["_policy"]]
        row["audit_rate"] = float(group["audit_rate"].mean())
        row["revision_rate"] = pooled_revision_rate(group)
    frame = pd.DataFrame(rows).drop(columns=["comparison", "_policy"])
    columns = [Column("Policy", text("policy"), align="l")]
    columns += [Column(h, cell_pm(n, d), latex=_delta_header(h)) for n, h, d in AGENTIC_METRICS]
    columns += [Column("Audit Rate", cell("audit_rate", 3)), Column("Revision Rate", cell("revision_rate", 3))]
    return ReportTable(
        key="agentic_effects",
        label="tab:auditability",
        title=title,
        caption=(
            "Paired effects of adding the LLM Planner/Auditor layer under the physics-constrained reward. Δ "
            "columns are RL+LLM minus RL over matched rollouts (mean ± sample std); the audit rate is the "
            "fraction of governance steps audited and the revision rate the fraction of audits that revised "
            "the action, both pooled over the policy's RL+LLM steps."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "paired rollouts"),
        notes=notes,
    )


def agentic_paired_deltas(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Appendix: RL+LLM minus raw RL for both rewards (policies in the report's one order)."""
    title = "Paired episode-level effects of the Planner/Auditor layer"
    pairs = [
        (AGENTIC_REWARD_LABELS[treated], base, treated)
        for treated, base in AGENTIC_BASE.items()
        if {base, treated} <= set(data.settings)
    ]
    if not pairs:
        return Skipped(
            "agentic_paired_deltas", title, "needs an agentic setting (llm / llm_no_physics) and its raw-RL setting"
        )
    rows, notes = _paired_rows(data, pairs, DETAIL_METRICS, paper_order)
    if not rows:
        return Skipped("agentic_paired_deltas", title, "no policy was evaluated both with and without the LLM layer")
    frame = pd.DataFrame(rows).drop(columns="_policy")
    columns = [
        Column("Comparison", text("comparison"), align="l"),
        Column("Policy", text("policy"), align="l"),
        Column("Δ Reward", cell_pm("cumulative_reward", 3), latex=r"$\Delta$ Reward"),
        Column("Δ Action Jitter", cell_pm("action_jitter", 4), latex=r"$\Delta$ Action Jitter"),
        Column("Δ Spatial Fairness", cell("spatial_fairness_index_mean", 4), latex=r"$\Delta$ Spatial Fairness"),
        Column(
            "Δ Artificial Liquidity", cell("artificial_liquidity_MWh_mean", 4), latex=r"$\Delta$ Artificial Liquidity"
        ),
        Column("Δ Slippage", cell("mean_slippage_mean", 4), latex=r"$\Delta$ Slippage"),
    ]
    return ReportTable(
        key="agentic_paired_deltas",
        label="tab:app-agentic-paired-deltas",
        title=title,
        caption=(
            "Paired episode-level effects of adding the LLM Planner/Auditor layer. Deltas are RL+LLM minus raw "
            'RL under matched run seed, policy, and episode ("Main": physics-penalised reward; '
            '"No-physics": the ablation); the last three columns are means.'
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "paired rollouts"),
        notes=notes,
    )
