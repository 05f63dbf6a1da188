"""The leaderboard's reward vs artificial-liquidity figure, with the Pareto front highlighted.

Each policy is one point per setting: mean artificial liquidity (x, lower is safer) against mean
cumulative reward (y, higher is better), with the reward's bootstrap interval as a vertical bar.
A policy is on the Pareto front when no other policy of the setting has at most its artificial
liquidity and at least its reward, and is strictly better in one of the two. A task without the
paper's board plots its ranked metric against one of its declared costs the same way
(:class:`ParetoAxes`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.text import Annotation
from matplotlib.transforms import Bbox

from ..figure_style import figure_bytes, new_figure, policy_colour
from ..naming import setting_label

#: Columns of the points frame (one row per policy and setting; leaderboard.csv has them).
X_COLUMN = "artificial_liquidity_MWh_mean"
Y_COLUMN = "cumulative_reward_mean"


@dataclass(frozen=True)
class ParetoAxes:
    """What the board's Pareto figure plots: a cost (x, lower is better) against the ranked metric (y)."""

    x_column: str
    y_column: str
    x_label: str
    y_label: str
    title: str


#: The solar market's figure: artificial liquidity against cumulative reward.
SOLAR_PARETO = ParetoAxes(
    X_COLUMN,
    Y_COLUMN,
    "Artificial liquidity (MWh, lower is safer)",
    "Mean cumulative reward",
    "Reward vs artificial liquidity",
)

#: Where a point's label may sit, tried in this order: offset (points) and alignment.
LABEL_SPOTS = (
    (5, 4, "left", "bottom"),
    (5, -4, "left", "top"),
    (-5, 4, "right", "bottom"),
    (-5, -4, "right", "top"),
    (0, 8, "center", "bottom"),
    (0, -8, "center", "top"),
    (12, 12, "left", "bottom"),
    (-12, -12, "right", "top"),
)


def pareto_front(liquidity_mwh: Sequence[float], reward: Sequence[float]) -> np.ndarray:
    """Boolean mask of the points no other point dominates (less or equal liquidity, more or equal
    reward, strictly better in one); points with a NaN coordinate are never on the front."""
    x, y = np.asarray(liquidity_mwh, dtype=float), np.asarray(reward, dtype=float)
    finite = np.isfinite(x) & np.isfinite(y)
    no_worse = (x[None, :] <= x[:, None]) & (y[None, :] >= y[:, None])
    better = (x[None, :] < x[:, None]) | (y[None, :] > y[:, None])
    dominated = (no_worse & better & finite[None, :]).any(axis=1)
    return finite & ~dominated


def pareto_figure(points: pd.DataFrame, axes_of: ParetoAxes = SOLAR_PARETO) -> dict[str, bytes]:
    """One panel per setting of ``points`` (columns ``setting``, ``policy``, the two means of
    ``axes_of`` and the y metric's ``_low``/``_high``); returns ``{"png": ..., "svg": ...}``."""
    x_column, y_column = axes_of.x_column, axes_of.y_column
    y_name = y_column.removesuffix("_mean")
    settings = list(dict.fromkeys(points["setting"]))
    policies = sorted(set(points["policy"]))
    ncols = min(len(settings), 2)
    nrows = -(-len(settings) // ncols)
    with new_figure(nrows, ncols, figsize=(5.0 * ncols, 3.6 * nrows + 0.3)) as (figure, axes):
        for ax in axes.ravel()[len(settings) :]:
            ax.set_visible(False)
        for ax, setting in zip(axes.ravel(), settings, strict=False):
            group = points[points["setting"] == setting].reset_index(drop=True)
            x, y = group[x_column].to_numpy(float), group[y_column].to_numpy(float)
            front = pareto_front(x, y)
            for i, row in group.iterrows():
                colour = policy_colour(row["policy"], policies)
                low, high = float(row[f"{y_name}_low"]), float(row[f"{y_name}_high"])
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
            order = np.argsort(x[front], kind="stable")
            ax.plot(x[front][order], y[front][order], color="black", linewidth=1.0, linestyle="--", zorder=2)
            ax.set_title(setting_label(setting))
            ax.set_xlabel(axes_of.x_label)
            ax.set_ylabel(axes_of.y_label)
            ax.margins(x=0.15, y=0.1)  # room for the labels of the outermost points
        figure.suptitle(f"{axes_of.title} (Pareto front: outlined points, dashed line)", fontsize=9)
        # Lay the figure out once, then fix it, so the labels are placed where they will be drawn.
        FigureCanvasAgg(figure)
        figure.draw_without_rendering()
        figure.set_layout_engine("none")
        for ax, setting in zip(axes.ravel(), settings, strict=False):
            group = points[points["setting"] == setting].reset_index(drop=True)
            x, y = group[x_column].to_numpy(float), group[y_column].to_numpy(float)
            place_labels(ax, x, y, [str(p) for p in group["policy"]], first=pareto_front(x, y))
        return figure_bytes(figure)


def place_labels(
    ax: Axes, x: np.ndarray, y: np.ndarray, labels: Sequence[str], first: np.ndarray | None = None
) -> list[Annotation]:
    """Label each point at the first of :data:`LABEL_SPOTS` where the label overlaps no label placed
    before it and no other point, and stays inside the axes (else at the first spot).

    The points marked in ``first`` (the Pareto front) are labelled first, then the others, each
    group from left to right. The axes' figure must have an Agg canvas and its final layout.
    """
    renderer = ax.figure.canvas.get_renderer()
    pixels = ax.transData.transform(np.column_stack([x, y]))
    markers = [Bbox.from_bounds(px - 4, py - 4, 8, 8) for px, py in pixels]
    priority = np.zeros(len(labels), dtype=bool) if first is None else np.asarray(first, dtype=bool)
    order = sorted(range(len(labels)), key=lambda i: (not priority[i], x[i] if np.isfinite(x[i]) else np.inf))
    placed: list[Bbox] = []
    annotations: list[Annotation] = []
    for i in order:
        for number, (dx, dy, ha, va) in enumerate((*LABEL_SPOTS, LABEL_SPOTS[0])):
            note = ax.annotate(
                labels[i], (x[i], y[i]), xytext=(dx, dy), textcoords="offset points", ha=ha, va=va, fontsize=7
            )
            if number == len(LABEL_SPOTS):
                break  # no free spot: the first one, overlapping
            box = note.get_window_extent(renderer)
            inside = ax.bbox.contains(box.x0, box.y0) and ax.bbox.contains(box.x1, box.y1)
            clash = any(box.overlaps(other) for other in placed)
            clash = clash or any(box.overlaps(m) for j, m in enumerate(markers) if j != i)
            if inside and not clash:
                break
            note.remove()
        placed.append(note.get_window_extent(renderer))
        annotations.append(note)
    return annotations
