"""City × hour heat maps (one panel per policy, shared colour scale): the liquidity ratio ℓ the
paper shows, and the city reward, which carries the spatial (fairness) signal: ℓ is one
market-wide action, so every city of an hour shows the same ℓ."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ....evaluation.settings import SETTING_MAIN
from ...figure_style import FigureFile, new_figure, save_figure
from ...loading import ReportData
from ...naming import paper_order, policy_label, setting_label
from ...options import ReportOptions
from ...table_model import Skipped

HEATMAPS = (
    ("city_hour_liquidity", "liquidity_ratio", "City × hour liquidity ratio", "Mean liquidity ratio ℓ", "YlGnBu"),
    ("city_hour_reward", "city_reward", "City × hour city reward", "Mean city reward", "viridis"),
)
NOTES = {
    "liquidity_ratio": "The liquidity ratio is one market-wide action, so all cities of an hour share it.",
    "city_reward": "City rewards split the reward pool by verified supply and violation rate (spatial fairness).",
}


def city_hour_heatmaps(data: ReportData, options: ReportOptions, out_dir: Path) -> list[FigureFile | Skipped]:
    """The liquidity-ratio and city-reward heat maps."""
    return [_heatmap(data, out_dir, *spec) for spec in HEATMAPS]


def _heatmap(
    data: ReportData, out_dir: Path, key: str, value: str, title: str, unit: str, cmap: str
) -> FigureFile | Skipped:
    """Mean ``value`` per city and hour of day, per policy, in the main setting.

    Runs without a main setting use their first setting (named in the title).
    """
    frame = data.city_hour
    if frame.empty:
        return Skipped(key, title, "the run has no city_hour_policy.csv")
    settings = [s for s in data.settings if s in set(frame["setting"])]
    if not settings:
        return Skipped(key, title, "city_hour_policy.csv has no rows of the run's settings")
    setting = SETTING_MAIN if SETTING_MAIN in settings else settings[0]
    frame = frame[frame["setting"] == setting]
    policies = paper_order(frame["policy"])
    heat = frame.groupby(["policy", "city", "hour"], sort=True)[value].mean()
    cities = sorted(frame["city"].unique())
    hours = sorted(frame["hour"].unique())
    grids = {p: heat.loc[p].unstack("hour").reindex(index=cities, columns=hours).to_numpy(float) for p in policies}
    vmin = min(float(np.nanmin(g)) for g in grids.values())
    vmax = max(float(np.nanmax(g)) for g in grids.values())
    ncols = min(3, len(policies))
    nrows = math.ceil(len(policies) / ncols)
    with new_figure(nrows, ncols, figsize=(3.3 * ncols + 0.8, 2.3 * nrows + 0.4), sharex=True, sharey=True) as (
        figure,
        axes,
    ):
        image = None
        for index, ax in enumerate(axes.flat):
            if index >= len(policies):
                ax.set_visible(False)
                continue
            policy = policies[index]
            image = ax.imshow(grids[policy], aspect="auto", cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
            ax.set_title(policy_label(policy))
            ax.set_yticks(range(len(cities)), cities)
            ax.set_xticks(range(0, len(hours), 6), [str(h) for h in hours[::6]])
            ax.grid(False)
            if index % ncols == 0:
                ax.set_ylabel("City")
            if index // ncols == nrows - 1:
                ax.set_xlabel("Hour of day")
        figure.colorbar(image, ax=axes, label=unit, shrink=0.9)
        figure.suptitle(f"{title} ({setting_label(setting)})")
        caption = (
            f"{title}: {unit.lower()} per city and hour of day for each policy ({setting_label(setting)} setting, "
            f"shared colour scale). {NOTES[value]}"
        )
        return save_figure(figure, out_dir, key, title, caption)
