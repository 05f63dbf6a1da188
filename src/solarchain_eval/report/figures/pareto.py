"""The leaderboard's reward vs artificial-liquidity figure, with the Pareto front highlighted.

Each policy is one point per setting: mean artificial liquidity (x, lower is safer) against mean
cumulative reward (y, higher is better), with the reward's bootstrap interval as a vertical bar.
A policy is on the Pareto front when no other policy of the setting has at most its artificial
liquidity and at least its reward, and is strictly better in one of the two.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..naming import setting_label
from .style import figure_bytes, new_figure, policy_colour

#: Columns of the points frame (one row per policy and setting; leaderboard.csv has them).
X_COLUMN = "artificial_liquidity_MWh_mean"
Y_COLUMN = "cumulative_reward_mean"


def pareto_front(liquidity_mwh: Sequence[float], reward: Sequence[float]) -> np.ndarray:
    """Boolean mask of the points no other point dominates (less or equal liquidity, more or equal
    reward, strictly better in one); points with a NaN coordinate are never on the front."""
    x, y = np.asarray(liquidity_mwh, dtype=float), np.asarray(reward, dtype=float)
    finite = np.isfinite(x) & np.isfinite(y)
    no_worse = (x[None, :] <= x[:, None]) & (y[None, :] >= y[:, None])
    better = (x[None, :] < x[:, None]) | (y[None, :] > y[:, None])
    dominated = (no_worse & better & finite[None, :]).any(axis=1)
    return finite & ~dominated


def pareto_figure(points: pd.DataFrame) -> dict[str, bytes]:
    """One panel per setting of ``points`` (columns ``setting``, ``policy``, the two means and
    ``cumulative_reward_low``/``_high``); returns ``{"png": ..., "svg": ...}``."""
    settings = list(dict.fromkeys(points["setting"]))
    policies = sorted(set(points["policy"]))
    ncols = min(len(settings), 2)
    nrows = -(-len(settings) // ncols)
    with new_figure(nrows, ncols, figsize=(5.0 * ncols, 3.6 * nrows + 0.3)) as (figure, axes):
        for ax in axes.ravel()[len(settings) :]:
            ax.set_visible(False)
        for ax, setting in zip(axes.ravel(), settings, strict=False):
            group = points[points["setting"] == setting].reset_index(drop=True)
            x, y = group[X_COLUMN].to_numpy(float), group[Y_COLUMN].to_numpy(float)
            front = pareto_front(x, y)
            for i, row in group.iterrows():
                colour = policy_colour(row["policy"], policies)
                low, high = float(row["cumulative_reward_low"]), float(row["cumulative_reward_high"])
                if np.isfinite(low) and np.isfinite(high):
                    ax.vlines(x[i], low, high, color=colour, alpha=0.5, linewidth=1.2)
                ax.scatter(
                    [x[i]],
                    [y[i]],
                    s=70 if front[i] else 36,
                    color=colour,
                    edgecolors="black" if front[i] else "none",
                    linewidths=1.4,
                    zorder=3,
                )
                ax.annotate(str(row["policy"]), (x[i], y[i]), xytext=(5, 4), textcoords="offset points", fontsize=7)
            order = np.argsort(x[front], kind="stable")
            ax.plot(x[front][order], y[front][order], color="black", linewidth=1.0, linestyle="--", zorder=2)
            ax.set_title(setting_label(setting))
            ax.set_xlabel("Artificial liquidity (MWh, lower is safer)")
            ax.set_ylabel("Mean cumulative reward")
        figure.suptitle("Reward vs artificial liquidity (Pareto front: outlined points, dashed line)", fontsize=9)
        return figure_bytes(figure)
