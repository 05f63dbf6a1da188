"""Per-setting performance tables: the main table, its appendix detail, the four-setting tables."""

from __future__ import annotations

import pandas as pd

from ....evaluation.settings import SETTING_MAIN
from ...loading import ReportData
from ...naming import (
    GOVERNANCE_LABELS,
    GOVERNANCE_ORDER,
    is_trained,
    is_user_agent,
    learned_order,
    paper_order,
    policy_label,
)
from ...options import ReportOptions
from ...table_model import Column, ReportTable, Skipped, basis_sentence, cell, cell_pm, integer, span, text
from .common import learned_rollouts, means, moments, size_fields, sizes_of

#: (metrics column, header, decimals) of the main table, in the paper's column order.
MAIN_METRICS = (
    ("cumulative_reward", "Cumulative Reward", 2),
    ("episode_volume", "Trading Volume", 3),
    ("physics_violation_rate", "Physics Violation Rate", 4),
    ("mean_slippage", "Mean Slippage", 4),
    ("artificial_liquidity_MWh", "Artificial Liquidity", 4),
)
#: (metrics column, header, decimals) of the four-setting tables.
SETTING_METRICS = (
    ("cumulative_reward", "Reward", 2),
    ("physics_violation_rate", "Violation", 4),
    ("artificial_liquidity_MWh", "Artificial Liquidity", 4),
    ("mean_slippage", "Slippage", 4),
    ("action_jitter", "Jitter", 4),
    ("spatial_fairness_index", "Fairness", 4),
)
NO_MAIN = "no rollouts in the main setting (physics-penalised reward, no LLM layer)"
NO_TRAINED = "the run has no learned policies of the package (PPO, SAC, DQN, ...); user agents are not pooled here"
USER_AGENTS_NOTE = "Rows marked (user agent) are agents evaluated from their specs, not trained by the grid."
NO_LEARNED = "the run has no learned policies (only rule baselines); this table covers PPO, SAC, DQN and other learners"


def main_performance(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """The paper's main table: mean ± sample std per policy in the main setting."""
    title = "Main benchmark performance"
    rollouts = data.rollouts(SETTING_MAIN)
    if rollouts.empty:
        return Skipped("main_performance", title, NO_MAIN)
    rows = []
    for policy in paper_order(rollouts["policy"]):
        group = rollouts[rollouts["policy"] == policy]
        rows.append(
            {"policy": policy_label(policy), **size_fields(group), **moments(group, [m for m, _, _ in MAIN_METRICS])}
        )
    frame = pd.DataFrame(rows)
    columns = [Column("Policy", text("policy"), align="l")]
    columns += [Column(header, cell_pm(name, digits)) for name, header, digits in MAIN_METRICS]
    return ReportTable(
        key="main_performance",
        label="tab:main-performance",
        title=title,
        caption=(
            "Main benchmark performance under the physics-constrained reward. Values are mean ± sample "
            "standard deviation (ddof=1) over all rollouts of each policy (run seeds × episodes). Higher "
            "cumulative reward and trading volume are better; lower physics violation, slippage, and "
            "artificial liquidity indicate safer market governance."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "rollouts"),
    )


def main_detail(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Appendix detail of the main setting: reward min/max and the violation range (policies in the report's one order)."""
    title = "Detailed main-setting episode summaries"
    rollouts = data.rollouts(SETTING_MAIN)
    if rollouts.empty:
        return Skipped("main_detail", title, NO_MAIN)
    rows = []
    for policy in paper_order(rollouts["policy"]):
        group = rollouts[rollouts["policy"] == policy]
        stats = moments(group, ["cumulative_reward", "physics_violation_rate"], extremes=True)
        stats |= means(group, ["episode_volume", "artificial_liquidity_MWh", "mean_slippage", "action_jitter"])
        rows.append({"policy": policy_label(policy), **size_fields(group), **stats})
    frame = pd.DataFrame(rows)
    columns = [
        Column("Policy", text("policy"), align="l"),
        Column("Rollouts", integer("n")),
        Column("Reward Mean", cell("cumulative_reward_mean", 2)),
        Column("Reward Min", cell("cumulative_reward_min", 2)),
        Column("Reward Max", cell("cumulative_reward_max", 2)),
        Column("Volume", cell("episode_volume", 3)),
        Column("Violation Mean", cell("physics_violation_rate_mean", 4)),
        Column("Violation Range", lambda r: span(r["physics_violation_rate_min"], r["physics_violation_rate_max"], 4)),
        Column("Artificial Liquidity", cell("artificial_liquidity_MWh", 4)),
    ]
    return ReportTable(
        key="main_detail",
        label="tab:app-main-detail",
        title=title,
        caption=(
            "Detailed main-setting episode summaries. Reward, volume, violation and artificial liquidity "
            "are aggregated over all rollouts per policy (the CSV adds slippage and action jitter)."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "rollouts"),
    )


def _setting_columns(first: list[Column]) -> list[Column]:
    return first + [Column(header, cell(name, digits)) for name, header, digits in SETTING_METRICS]


def four_setting_learned(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Appendix: per setting and learned policy, the means of the six risk metrics."""
    title = "Four-setting summaries for learned policies"
    learned = learned_rollouts(data)
    if learned.empty:
        return Skipped("four_setting_learned", title, NO_LEARNED)
    rows = []
    for setting in GOVERNANCE_ORDER:
        in_setting = learned[learned["setting"] == setting]
        for policy in learned_order(in_setting["policy"]):
            group = in_setting[in_setting["policy"] == policy]
            rows.append(
                {
                    "setting": GOVERNANCE_LABELS[setting],
                    "policy": policy_label(policy),
                    **size_fields(group),
                    **means(group, [m for m, _, _ in SETTING_METRICS]),
                }
            )
    frame = pd.DataFrame(rows)
    absent = [GOVERNANCE_LABELS[s] for s in GOVERNANCE_ORDER if s not in set(learned["setting"])]
    columns = _setting_columns(
        [
            Column("Setting", text("setting"), align="l"),
            Column("Policy", text("policy"), align="l"),
            Column("Rollouts", integer("n"), align="r"),
        ]
    )
    return ReportTable(
        key="four_setting_learned",
        label="tab:app-four-setting-learned",
        title=title,
        caption=(
            "Four-setting summaries for learned policies (means over each row's rollouts across run seeds). "
            "These values support the paired physics-removal deltas and show how the LLM governance layer "
            "changes the setting-level risk profile."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "rollouts"),
        notes=([f"Settings without learned rollouts in this run: {', '.join(absent)}."] if absent else [])
        + ([USER_AGENTS_NOTE] if learned["policy"].map(is_user_agent).any() else []),
    )


def four_setting_aggregate(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Appendix: per setting, the mean over every learned-policy rollout (PPO, SAC, DQN pooled;
    user agents are not pooled with them)."""
    title = "Aggregate learned-policy means by setting"
    learned = learned_rollouts(data)
    learned = learned[learned["policy"].map(is_trained)]
    if learned.empty:
        return Skipped("four_setting_aggregate", title, NO_TRAINED)
    rows = []
    for setting in GOVERNANCE_ORDER:
        group = learned[learned["setting"] == setting]
        if group.empty:
            continue
        rows.append(
            {
                "setting": GOVERNANCE_LABELS[setting],
                "policies": "/".join(policy_label(p) for p in learned_order(group["policy"])),
                **size_fields(group),
                **means(group, [m for m, _, _ in SETTING_METRICS]),
            }
        )
    frame = pd.DataFrame(rows)
    return ReportTable(
        key="four_setting_aggregate",
        label="tab:app-four-setting-aggregate",
        title=title,
        caption=(
            "Aggregate learned-policy means by setting: each row averages every learned-policy rollout of "
            "the setting (the policies column of the CSV names them)."
        ),
        columns=_setting_columns([Column("Setting", text("setting"), align="l")]),
        data=frame,
        basis=basis_sentence(sizes_of(frame), "rollouts"),
        notes=(
            [f"Every row pools {rows[0]['policies']}."]
            if len({r["policies"] for r in rows}) == 1
            else [f"{r['setting']}: pooled over {r['policies']}." for r in rows]
        ),
    )


__all__ = ["main_performance", "main_detail", "four_setting_learned", "four_setting_aggregate"]
