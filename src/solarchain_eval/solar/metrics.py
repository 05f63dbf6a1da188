"""The solar market's episode metrics (docs/metrics.md), computed with numpy exactly as the original release does."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..records_schema import METRIC_NAMES as METRIC_NAMES  # the column order, re-exported


def max_drawdown(series: np.ndarray) -> float:
    """max_t 1 - x_t / max_{s<=t} x_s over the post-step values (the initial value excluded)."""
    values = np.asarray(series, dtype=np.float64)
    if values.size == 0:
        return 0.0
    peaks = np.maximum.accumulate(values)
    return float(np.max(1.0 - values / np.maximum(peaks, 1e-12)))


def action_jitter(actions: np.ndarray) -> float:
    """Mean L1 distance between consecutive executed actions (float32 promoted to float64)."""
    arr = np.asarray(actions, dtype=np.float64)
    if arr.ndim != 2 or len(arr) < 2:
        return 0.0
    return float(np.mean(np.linalg.norm(np.diff(arr, axis=0), ord=1, axis=1)))


def spatial_fairness_index(city_totals: np.ndarray) -> float:
    """Population variance of the cities' episode rewards over their mean absolute value."""
    values = np.asarray(city_totals, dtype=np.float64)
    if values.size == 0:
        return 0.0
    return float(np.var(values) / max(float(np.mean(np.abs(values))), 1e-9))


def episode_metrics(
    reward: np.ndarray,
    matched_mwh: np.ndarray,
    violation_rate: np.ndarray,
    liquidity: np.ndarray,
    token_price: np.ndarray,
    actions: np.ndarray,
    slippage: np.ndarray,
    artificial_liquidity_mwh: np.ndarray,
    city_totals: np.ndarray,
) -> dict[str, float]:
    """All episode metrics (docs/metrics.md) of one episode from its per-step arrays.

    ``actions`` is the (T, 3) array of executed float32 actions; ``city_totals`` the cities'
    accumulated rewards.
    """
    return {
        "cumulative_reward": float(np.sum(reward)),
        "episode_volume": float(np.sum(matched_mwh)),
        "physics_violation_rate": float(np.mean(violation_rate)),
        "max_drawdown": max_drawdown(liquidity),
        "max_token_drawdown": max_drawdown(token_price),
        "action_jitter": action_jitter(actions),
        "mean_slippage": float(np.mean(slippage)),
        "spatial_fairness_index": spatial_fairness_index(city_totals),
        "artificial_liquidity_MWh": float(np.sum(artificial_liquidity_mwh)),
        "final_liquidity": float(liquidity[-1]),
        "final_token_price": float(token_price[-1]),
    }


#: The executed action's step fields, in lever order.
ACTION_FIELDS = ("reward_ratio", "liquidity_ratio", "burn_rate")


def episode_metrics_from_steps(steps: Mapping[str, list], city_totals: np.ndarray) -> dict[str, float]:
    """:func:`episode_metrics` of one episode from its per-step record columns (``STEP_INFO_KEYS``)."""
    actions = np.column_stack([np.asarray(steps[c], dtype=np.float32) for c in ACTION_FIELDS])
    return episode_metrics(
        reward=np.asarray(steps["reward"]),
        matched_mwh=np.asarray(steps["matched_energy_MWh"]),
        violation_rate=np.asarray(steps["physics_violation_rate"]),
        liquidity=np.asarray(steps["liquidity"]),
        token_price=np.asarray(steps["token_price"]),
        actions=actions,
        slippage=np.asarray(steps["slippage"]),
        artificial_liquidity_mwh=np.asarray(steps["artificial_liquidity_MWh"]),
        city_totals=city_totals,
    )
