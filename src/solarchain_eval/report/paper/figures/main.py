"""Main-setting figures: reward distribution, utility–safety frontier, reward trajectory, and
the trustworthiness metrics (violation, artificial liquidity, slippage) per policy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.ticker import MaxNLocator

from ....evaluation.settings import SETTING_MAIN
from ...figure_style import FigureFile, label_categories, new_figure, points_with_mean, policy_colour, save_figure
from ...loading import ReportData
from ...naming import paper_order, policy_label
from ...options import ReportOptions
from ...statistics import t_interval
from ...table_model import Skipped

NO_MAIN = "no rollouts in the main setting"


def _main(data: ReportData) -> tuple[pd.DataFrame, list[str]]:
    rollouts = data.rollouts(SETTING_MAIN)
    return rollouts, paper_order(rollouts["policy"])


def reward_distribution(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Box plot of rollout-level cumulative reward per policy with every rollout as a point."""
    key, title = "reward_distribution", "Rollout-level cumulative reward"
    rollouts, policies = _main(data)
    if rollouts.empty:
        return Skipped(key, title, NO_MAIN)
    rng = np.random.default_rng(options.seed)
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        values = [rollouts.loc[rollouts["policy"] == p, "cumulative_reward"].to_numpy(float) for p in policies]
        box = ax.boxplot(values, positions=range(len(policies)), widths=0.55, showfliers=False, patch_artist=True)
        for patch, policy in zip(box["boxes"], policies, strict=True):
            patch.set(facecolor=policy_colour(policy, policies), alpha=0.25, edgecolor=policy_colour(policy, policies))
        for median in box["medians"]:
            median.set(color="black", linewidth=1.2)
        for i, (policy, v) in enumerate(zip(policies, values, strict=True)):
            ax.scatter(
                i + rng.uniform(-0.16, 0.16, v.size),
                v,
                s=8,
                alpha=0.45,
                color=policy_colour(policy, policies),
                linewidths=0,
            )
        label_categories(ax, [policy_label(p) for p in policies])
        ax.set_ylabel("Cumulative reward per episode")
        ax.set_title(title)
        return save_figure(
            figure,
            out_dir,
            key,
            title,
            "Rollout-level cumulative reward in the main setting; boxes span the quartiles, points are rollouts.",
        )


def utility_safety_frontier(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Reward vs physics violation per rollout; marker area grows with artificial liquidity."""
    key, title = "utility_safety_frontier", "Utility–safety frontier"
    rollouts, policies = _main(data)
    if rollouts.empty:
        return Skipped(key, title, NO_MAIN)
    largest = max(float(rollouts["artificial_liquidity_MWh"].max()), 1e-12)
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for policy in policies:
            group = rollouts[rollouts["policy"] == policy]
            sizes = 8 + 120 * np.clip(group["artificial_liquidity_MWh"].to_numpy(float), 0.0, None) / largest
            ax.scatter(
                group["physics_violation_rate"],
                group["cumulative_reward"],
                s=sizes,
                alpha=0.45,
                color=policy_colour(policy, policies),
                label=policy_label(policy),
                linewidths=0,
            )
        ax.set_xlabel("Physics violation rate (lower is safer)")
        ax.set_ylabel("Cumulative reward")
        ax.set_title(title)
        legend = ax.legend(loc="best", markerscale=0.8)
        for handle in legend.legend_handles:
            handle.set_sizes([30])
        caption = (
            "Utility–safety frontier. Each point is one rollout; larger markers indicate higher artificial "
            f"liquidity (area ∝ MWh, largest = {largest:.3f} MWh)."
        )
        return save_figure(figure, out_dir, key, title, caption)


def trajectory(ax: Axes, frame: pd.DataFrame, value: str, colour: str, label: str, confidence: float) -> bool:
    """Mean over run seeds per episode index with a Student-t band across seeds.

    Returns whether a band was drawn (none with a single run seed), so captions can say so.
    """
    per_episode = frame.groupby("episode", sort=True)[value]
    episodes = np.array(sorted(per_episode.groups))
    intervals = [t_interval(per_episode.get_group(e).to_numpy(float), confidence) for e in episodes]
    mean = np.array([i.estimate for i in intervals])
    ax.plot(episodes, mean, color=colour, linewidth=1.4, label=label)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    low, high = np.array([i.low for i in intervals]), np.array([i.high for i in intervals])
    if np.isfinite(low).any():
        ax.fill_between(episodes, low, high, color=colour, alpha=0.15, linewidth=0)
        return True
    return False


def band_phrase(drawn: bool, confidence: float, seeds: int) -> str:
    """What the trajectory figure's shading shows, in words (only what was drawn)."""
    if drawn:
        return f"{confidence:.0%} Student-t bands across the {seeds} run seeds"
    return f"no confidence band ({seeds} run seed{'s' if seeds != 1 else ''}: too few for one)"


def reward_trajectory(data: ReportData, options: ReportOptions, out_dir: Path) -> FigureFile | Skipped:
    """Episode-wise cumulative reward: mean over run seeds, with a band across seeds when drawn."""
    key, title = "reward_trajectory", "Episode-wise reward trajectory"
    rollouts, policies = _main(data)
    if rollouts.empty:
        return Skipped(key, title, NO_MAIN)
    seeds = rollouts["run_seed"].nunique()
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        drawn = False
        for policy in policies:
            group = rollouts[rollouts["policy"] == policy]
            drawn |= trajectory(
                ax,
                group,
                "cumulative_reward",
                policy_colour(policy, policies),
                policy_label(policy),
                options.confidence,
            )
        ax.set_xlabel("Episode index within a run seed")
        ax.set_ylabel("Cumulative reward")
        ax.set_title(title)
        ax.legend(loc="best", ncols=2)
        band = band_phrase(drawn, options.confidence, seeds)
        return save_figure(
            figure, out_dir, key, title, f"Episode-wise reward trajectory: mean over run seeds with {band}."
        )


TRUST_METRICS = (
    ("trust_violation", "physics_violation_rate", "Physics violation rate", "Physics violation rate"),
    ("trust_artificial_liquidity", "artificial_liquidity_MWh", "Artificial liquidity", "Artificial liquidity (MWh)"),
    ("trust_slippage", "mean_slippage", "Mean slippage", "Mean slippage"),
)


def _trust_figure(
    data: ReportData, options: ReportOptions, out_dir: Path, key: str, metric: str, title: str, ylabel: str
) -> FigureFile | Skipped:
    rollouts, policies = _main(data)
    if rollouts.empty:
        return Skipped(key, title, NO_MAIN)
    rng = np.random.default_rng(options.seed)
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for i, policy in enumerate(policies):
            values = rollouts.loc[rollouts["policy"] == policy, metric].to_numpy(float)
            colour = policy_colour(policy, policies)
            ax.bar(i, values.mean(), width=0.6, color=colour, alpha=0.25, edgecolor=colour)
            points_with_mean(ax, i, values, colour, rng)
        label_categories(ax, [policy_label(p) for p in policies])
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        caption = (
            f"{title} per policy in the main benchmark: bars and lines are means, translucent "
            f"points are individual rollouts."
        )
        return save_figure(figure, out_dir, key, title, caption)


def trust_figures(data: ReportData, options: ReportOptions, out_dir: Path) -> list[FigureFile | Skipped]:
    """Violation, artificial liquidity and slippage per policy (one figure each)."""
    return [
        _trust_figure(data, options, out_dir, key, metric, title, ylabel)
        for key, metric, title, ylabel in TRUST_METRICS
    ]
