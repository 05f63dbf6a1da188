"""Comparing two training backends (or any two runs of the same grid): per policy and setting, the
difference of each metric's mean with a cluster-bootstrap interval over start days.

Both runs must evaluate the same episodes (the same run seeds, episode seeds and protocol); the
interval resamples start days jointly for the two runs (:func:`bootstrap_mean_difference`),
so a day that is hard for both cancels out of the difference.
"""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from .statistics import DEFAULT_SEED, bootstrap_mean_difference

#: The metrics the backend comparison reports (metrics.csv columns).
COMPARED_METRICS = ("cumulative_reward", "physics_violation_rate", "artificial_liquidity_MWh", "mean_slippage")


def compare_runs(
    base: pd.DataFrame,
    other: pd.DataFrame,
    metrics: Sequence[str] = COMPARED_METRICS,
    *,
    n_resamples: int = 2000,
    seed: int = DEFAULT_SEED,
) -> pd.DataFrame:
    """``mean(other) - mean(base)`` per policy, setting and metric, with a 95 % start-day bootstrap interval.

    Parameters
    ----------
    base, other : DataFrame
        metrics.csv rows (policy, setting, run_seed, episode, episode_seed, start_hour, metrics).
    metrics : sequence of str
    n_resamples, seed
        Bootstrap resamples and the seed of the resampling stream.

    Returns
    -------
    DataFrame
        One row per policy, setting and metric: ``base``, ``other``, ``difference``, ``low``, ``high``.

    Raises
    ------
    ValueError
        The runs evaluated different episodes for a policy and setting present in both.
    """
    key = ["run_seed", "episode", "episode_seed", "start_hour"]
    rows = []
    shared = base[["policy", "setting"]].drop_duplicates().merge(other[["policy", "setting"]].drop_duplicates())
    for policy, setting in shared.itertuples(index=False):
        a = base[(base["policy"] == policy) & (base["setting"] == setting)].sort_values(key)
        b = other[(other["policy"] == policy) & (other["setting"] == setting)].sort_values(key)
        if not a[key].reset_index(drop=True).equals(b[key].reset_index(drop=True)):
            raise ValueError(f"{policy} in {setting}: the two runs evaluated different episodes")
        for metric in metrics:
            interval = bootstrap_mean_difference(
                b[metric], b["start_hour"], a[metric], a["start_hour"], n_resamples=n_resamples, seed=seed
            )
            rows.append(
                {
                    "policy": policy,
                    "setting": setting,
                    "metric": metric,
                    "base": float(a[metric].mean()),
                    "other": float(b[metric].mean()),
                    "difference": interval.estimate,
                    "low": interval.low,
                    "high": interval.high,
                }
            )
    return pd.DataFrame(rows)
