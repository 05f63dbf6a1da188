"""Physics-ablation figures (learned policies): paired no-physics deltas of artificial
liquidity, artificial liquidity across the four settings, and its episode-wise trajectories."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...figure_style import SETTING_COLOURS, FigureFile, label_categories, new_figure, policy_colour, save_figure
from ...loading import ReportData
from ...naming import ABLATION_PAIRS, GOVERNANCE_LABELS, GOVERNANCE_ORDER, learned_order, policy_label
from ...options import ReportOptions
from ...statistics import paired_deltas
from ...table_model import Skipped
from .main import band_phrase, trajectory

METRIC = "artificial_liquidity_MWh"
MARKERS = {"main": "o", "llm": "^"}


def paired_no_physics_delta(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Per learned policy: paired Δ artificial liquidity (no-physics − physics) for RL and RL+LLM."""
    key, title = "paired_no_physics_delta", "Paired no-physics Δ artificial liquidity"
    pairs = [(base, treated) for base, treated in ABLATION_PAIRS.items() if {base, treated} <= set(data.settings)]
    deltas = {base: paired_deltas(data.metrics, base, treated, [METRIC]).frame for base, treated in pairs}
    policies = learned_order(p for frame in deltas.values() for p in frame["policy"])
    if not policies:
        return Skipped(key, title, "needs learned policies in a physics setting and its no-physics ablation")
    rng = np.random.default_rng(options.seed)
    offsets = {"main": -0.18, "llm": 0.18} if len(pairs) == 2 else {base: 0.0 for base, _ in pairs}
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for i, policy in enumerate(policies):
            colour = policy_colour(policy, policies)
            for base, frame in deltas.items():
                values = frame.loc[frame["policy"] == policy, METRIC].to_numpy(float)
                if values.size == 0:
                    continue
                x = i + offsets[base]
                ax.scatter(
                    x + rng.uniform(-0.07, 0.07, values.size),
                    values,
                    s=8,
                    color=colour,
                    alpha=0.3,
                    linewidths=0,
                    marker=MARKERS[base],
                )
                ax.scatter([x], [values.mean()], s=60, color=colour, edgecolors="black", marker=MARKERS[base], zorder=3)
        for base in deltas:
            ax.scatter(
                [],
                [],
                marker=MARKERS[base],
                color="white",
                edgecolors="black",
                label=f"{GOVERNANCE_LABELS[base]} (mean)",
            )
        ax.axhline(0.0, color="black", linewidth=0.8)
        label_categories(ax, [policy_label(p) for p in policies])
        ax.set_ylabel("Δ artificial liquidity (MWh)")
        ax.set_title(title)
        ax.legend(loc="best")
        caption = (
            "Paired without-constraints artificial-liquidity deltas (no-physics minus physics-penalised, matched on "
            "policy, run seed and episode) for RL and RL+LLM; translucent points are pairs, large markers means."
        )
        return save_figure(figure, out_dir, key, title, caption)


def liquidity_four_settings(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Mean artificial liquidity per learned policy in each setting, with rollout points."""
    key, title = "liquidity_four_settings", "Artificial liquidity across settings"
    learned = data.metrics[data.metrics["policy"].isin(learned_order(data.metrics["policy"]))]
    if learned.empty:
        return Skipped(key, title, "the run has no learned policies")
    settings = [s for s in GOVERNANCE_ORDER if s in set(learned["setting"])]
    policies = learned_order(learned["policy"])
    rng = np.random.default_rng(options.seed)
    width = 0.8 / len(settings)
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for j, setting in enumerate(settings):
            colour = SETTING_COLOURS[setting]
            for i, policy in enumerate(policies):
                values = learned.loc[(learned["setting"] == setting) & (learned["policy"] == policy), METRIC].to_numpy(
                    float
                )
                if values.size == 0:
                    continue
                x = i - 0.4 + width * (j + 0.5)
                ax.bar(
                    x,
                    values.mean(),
                    width=width * 0.9,
                    color=colour,
                    alpha=0.35,
                    edgecolor=colour,
                    label=GOVERNANCE_LABELS[setting] if i == 0 else None,
                )
                ax.scatter(
                    x + rng.uniform(-width / 4, width / 4, values.size),
                    values,
                    s=5,
                    color=colour,
                    alpha=0.35,
                    linewidths=0,
                )
        label_categories(ax, [policy_label(p) for p in policies])
        ax.set_ylabel("Artificial liquidity (MWh)")
        ax.set_title(title)
        ax.legend(loc="best")
        caption = "Artificial liquidity of learned policies across RL, RL+LLM and their without-constraints ablations; bars are means, points rollouts."
        return save_figure(figure, out_dir, key, title, caption)


def liquidity_trajectories(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Episode-wise artificial liquidity per setting (learned policies pooled), band across seeds."""
    key, title = "liquidity_trajectories", "Artificial-liquidity trajectories"
    learned = data.metrics[data.metrics["policy"].isin(learned_order(data.metrics["policy"]))]
    if learned.empty:
        return Skipped(key, title, "the run has no learned policies")
    seeds = learned["run_seed"].nunique()
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        drawn = False
        for setting in GOVERNANCE_ORDER:
            frame = learned[learned["setting"] == setting]
            if frame.empty:
                continue
            # One value per (run seed, episode): the mean over the learned policies.
            per_seed = frame.groupby(["run_seed", "episode"], as_index=False)[METRIC].mean()
            drawn |= trajectory(
                ax, per_seed, METRIC, SETTING_COLOURS[setting], GOVERNANCE_LABELS[setting], options.confidence
            )
        ax.set_xlabel("Episode index within a run seed")
        ax.set_ylabel("Artificial liquidity (MWh)")
        ax.set_title(title)
        ax.legend(loc="best")
        caption = (
            "Episode-wise artificial-liquidity trajectories for the learned-agent settings: mean over learned "
            f"policies and run seeds, with {band_phrase(drawn, options.confidence, seeds)}."
        )
        return save_figure(figure, out_dir, key, title, caption)
