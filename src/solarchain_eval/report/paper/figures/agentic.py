"""Planner/Auditor figures: action-jitter change, paired deltas, step-level pre-audit jitter (κ)
vs auditor action delta, and the case study's action revision and context."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.patches import Patch
from scipy import stats

from ....evaluation.settings import SETTING_AGENTIC, SETTING_MAIN
from ...figure_style import FigureFile, label_categories, new_figure, policy_colour, save_figure
from ...loading import ReportData
from ...naming import GOVERNANCE_LABELS, governance_layer, learned_order, paper_order, policy_label, setting_label
from ...options import ReportOptions
from ...statistics import paired_deltas
from ...table_model import Skipped
from ..casestudy import episode_steps, select_case

NEEDS_PAIR = "needs learned policies in both the main setting and the agentic setting 'llm'"


def _save(figure, out_dir: Path, key: str, title: str, caption: str, data: ReportData) -> FigureFile:
    """save_figure, with the planner and auditor that ran in the title and caption (not "LLM" when
    the rule layer ran; the plot's own title stays short)."""
    layer = governance_layer(data.metrics, data.metadata)
    return save_figure(figure, out_dir, key, f"{title} ({layer})", f"{caption} Planner/Auditor: {layer}.")


def jitter_change(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Mean action jitter per learned policy with (RL+LLM) and without (RL) the layer."""
    key, title = "jitter_change", "Action jitter with the Planner/Auditor"
    metrics = data.metrics
    policies = [
        p
        for p in learned_order(metrics["policy"])
        if {SETTING_MAIN, SETTING_AGENTIC} <= set(metrics.loc[metrics["policy"] == p, "setting"])
    ]
    if not policies:
        return Skipped(key, title, NEEDS_PAIR)
    rng = np.random.default_rng(options.seed)
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for i, policy in enumerate(policies):
            colour = policy_colour(policy, policies)
            for offset, setting, alpha, hatch in ((-0.2, SETTING_MAIN, 0.25, None), (0.2, SETTING_AGENTIC, 0.6, "//")):
                values = metrics.loc[
                    (metrics["policy"] == policy) & (metrics["setting"] == setting), "action_jitter"
                ].to_numpy(float)
                ax.bar(i + offset, values.mean(), width=0.36, color=colour, alpha=alpha, edgecolor=colour, hatch=hatch)
                ax.scatter(
                    i + offset + rng.uniform(-0.1, 0.1, values.size), values, s=5, color=colour, alpha=0.4, linewidths=0
                )
        label_categories(ax, [policy_label(p) for p in policies])
        ax.set_ylabel("Action jitter (mean L1 change per step)")
        ax.set_title(title)
        ax.legend(
            handles=[
                Patch(facecolor="#888888", alpha=0.25, edgecolor="#888888", label=GOVERNANCE_LABELS[SETTING_MAIN]),
                Patch(
                    facecolor="#888888",
                    alpha=0.6,
                    edgecolor="#888888",
                    hatch="//",
                    label=GOVERNANCE_LABELS[SETTING_AGENTIC],
                ),
            ],
            loc="best",
        )
        caption = "Action stability: mean action jitter of each learned policy without (RL) and with (RL+LLM) the Planner/Auditor layer; points are rollouts."
        return _save(figure, out_dir, key, title, caption, data)


def agentic_delta_scatter(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Paired RL+LLM − RL changes: Δ action jitter (x) vs Δ artificial liquidity (y) per rollout."""
    key, title = "agentic_paired_deltas", "Paired RL+LLM − RL changes"
    if not {SETTING_MAIN, SETTING_AGENTIC} <= set(data.settings):
        return Skipped(key, title, NEEDS_PAIR)
    deltas = paired_deltas(
        data.metrics, SETTING_MAIN, SETTING_AGENTIC, ["action_jitter", "artificial_liquidity_MWh"]
    ).frame
    policies = learned_order(deltas["policy"])
    if not policies:
        return Skipped(key, title, NEEDS_PAIR)
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for policy in policies:
            group = deltas[deltas["policy"] == policy]
            colour = policy_colour(policy, policies)
            ax.scatter(
                group["action_jitter"], group["artificial_liquidity_MWh"], s=10, alpha=0.35, color=colour, linewidths=0
            )
            ax.scatter(
                [group["action_jitter"].mean()],
                [group["artificial_liquidity_MWh"].mean()],
                s=90,
                marker="X",
                color=colour,
                edgecolors="black",
                label=policy_label(policy),
                zorder=3,
            )
        ax.axhline(0.0, color="black", linewidth=0.8)
        ax.axvline(0.0, color="black", linewidth=0.8)
        ax.set_xlabel("Δ action jitter (RL+LLM − RL)")
        ax.set_ylabel("Δ artificial liquidity (MWh)")
        ax.set_title(title)
        ax.legend(loc="best")
        caption = "Paired RL+LLM-minus-RL changes in action jitter and artificial liquidity per matched rollout (main reward); crosses are policy means."
        return _save(figure, out_dir, key, title, caption, data)


def audit_step_delta(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Audited steps: pre-audit jitter κ (x) vs the Auditor's action delta (y), with Spearman ρ."""
    key, title = "audit_step_delta", "Pre-audit jitter κ vs Auditor action delta"
    logs = data.logs
    audited = logs[logs["audited"].astype(bool)] if not logs.empty else logs
    if audited.empty:
        return Skipped(key, title, "the run has no audited agentic log steps")
    policies = paper_order(audited["policy"])
    kappa, delta = audited["kappa"].to_numpy(float), audited["action_delta"].to_numpy(float)
    rho = stats.spearmanr(kappa, delta).statistic if len(audited) > 2 else float("nan")
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for policy in policies:
            group = audited[audited["policy"] == policy]
            ax.scatter(
                group["kappa"],
                group["action_delta"],
                s=9,
                alpha=0.4,
                color=policy_colour(policy, policies),
                label=policy_label(policy),
                linewidths=0,
            )
        ax.set_xlabel("Pre-audit action jitter κ (L1)")
        ax.set_ylabel("Auditor action delta (L1)")
        ax.set_title(f"{title} (Spearman ρ = {rho:.2f})")
        ax.legend(loc="best")
        caption = (
            f"Step-level relationship between pre-audit action jitter κ and the Auditor's "
            f"action delta over {len(audited)} audited steps (all agentic settings); Spearman ρ = {rho:.2f}."
        )
        return _save(figure, out_dir, key, title, caption, data)


COMPONENTS = ("reward ratio α", "liquidity ratio ℓ", "burn rate b")


def case_action_revision(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """The case study's proposed vs audited final action, per component."""
    key, title = "case_action_revision", "Selected action revision"
    case, _ = select_case(data.logs, options) if not data.logs.empty else (None, "")
    if case is None:
        return Skipped(key, title, "the agentic logs hold no revised audit")
    colour = policy_colour(case["policy"], [case["policy"]])
    with new_figure(figsize=(4.6, 3.4)) as (figure, axes):
        ax = axes[0, 0]
        x = np.arange(3)
        ax.bar(
            x - 0.18,
            case["proposed_action"],
            width=0.34,
            color=colour,
            alpha=0.3,
            edgecolor=colour,
            label="RL proposed",
        )
        ax.bar(
            x + 0.18, case["final_action"], width=0.34, color=colour, alpha=0.9, edgecolor=colour, label="Audited final"
        )
        label_categories(ax, list(COMPONENTS))
        ax.set_ylabel("Action value")
        ax.set_title(f"{title}: {policy_label(case['policy'])}, {setting_label(case['setting'])}")
        ax.legend(loc="best")
        caption = (
            f"Selected action revision ({policy_label(case['policy'])} / {setting_label(case['setting'])}, run seed "
            f"{int(case['run_seed'])}, episode {int(case['episode'])}, step {int(case['step'])}): action delta "
            f"{float(case['action_delta']):.3f}."
        )
        return _save(figure, out_dir, key, title, caption, data)


def case_context(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """The case's episode: risk signals per step with audited steps marked, and ℓ proposed vs final."""
    key, title = "case_context", "Context of the audited steps"
    case, _ = select_case(data.logs, options) if not data.logs.empty else (None, "")
    if case is None:
        return Skipped(key, title, "the agentic logs hold no revised audit")
    steps = episode_steps(data.logs, case)
    audited = steps["audited"].astype(bool).to_numpy()
    colour = policy_colour(case["policy"], [case["policy"]])
    with new_figure(2, 1, figsize=(5.2, 4.4), sharex=True) as (figure, axes):
        top, bottom = axes[0, 0], axes[1, 0]
        for step in steps.loc[audited, "step"]:
            for ax in (top, bottom):
                ax.axvspan(step - 0.5, step + 0.5, color="#999999", alpha=0.15, linewidth=0)
        top.plot(steps["step"], steps["raw_violation_rate"], marker=".", color="#d55e00", label="raw violation rate ν")
        top.plot(steps["step"], steps["supply_gap"], marker=".", color="#0072b2", label="supply gap")
        top.set_ylabel("Risk signal")
        top.legend(loc="best")
        top.set_title(
            f"{policy_label(case['policy'])}, {setting_label(case['setting'])}: episode "
            f"{int(case['episode'])} (shaded: audited)"
        )
        proposed = np.array([a[1] for a in steps["proposed_action"]])
        final = np.array([a[1] for a in steps["final_action"]])
        bottom.plot(steps["step"], proposed, marker="o", markersize=3, color=colour, alpha=0.45, label="ℓ proposed")
        bottom.plot(steps["step"], final, marker="o", markersize=3, color=colour, label="ℓ final")
        bottom.scatter(
            [case["step"]], [case["final_action"][1]], marker="*", s=160, color="black", zorder=4, label="selected step"
        )
        bottom.set_xlabel("Step (hour of the episode)")
        bottom.set_ylabel("Liquidity ratio ℓ")
        bottom.legend(loc="best")
        caption = (
            "Context of the case study's episode: raw violation rate and supply gap per step, audited steps shaded, "
            "and the liquidity ratio the policy proposed vs the one executed after the Auditor; the star marks the "
            "selected step."
        )
        return _save(figure, out_dir, key, title, caption, data)
