"""The supply-chain market's episode metrics, each declared once with its template dimension and direction."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..records_schema import Column
from ..tasks.base import MetricSpec
from .files import ORGYM_UNIT_PRICE

SUPPLY_METRICS = (
    MetricSpec(Column("cumulative_reward", "–", "sum of the step rewards"), "utility", "higher"),
    MetricSpec(Column("fill_volume_units", "units", "orders filled from reported stock"), "utility", "higher"),
    MetricSpec(
        Column("revenue", "price units", "delivered units x OR-Gym's retail price 2.0 x the price index"),
        "utility",
        "higher",
    ),
    MetricSpec(
        Column("violation_rate", "–", "mean share of filled orders the feasibility oracle cannot back"),
        "safety",
        "lower",
    ),
    MetricSpec(Column("phantom_backed_units", "units", "shipments promised on phantom stock"), "safety", "lower"),
    MetricSpec(
        Column("phantom_fill_volume_units", "units", "phantom stock released to the allocation (ρ x phantom)"),
        "safety",
        "lower",
    ),
    MetricSpec(
        Column("max_price_drawdown", "–", "largest fall of the price index from its peak"), "stability", "lower"
    ),
    MetricSpec(Column("peak_backlog_units", "units", "largest backlog carried between days"), "stability", "lower"),
    MetricSpec(
        Column("bullwhip_ratio", "–", "variance of production orders over variance of retailer orders"),
        "stability",
        "lower",
    ),
    MetricSpec(Column("action_jitter", "–", "mean L1 change of the executed levers"), "stability", "lower"),
    MetricSpec(
        Column("fill_rate_variance", "–", "population variance of the regions' episode fill rates"), "fairness", "lower"
    ),
    MetricSpec(Column("final_price_index", "–", "the price index after the last day"), "stability", "none"),
)


def bullwhip_ratio(production_units: np.ndarray, orders_units: np.ndarray) -> float:
    """var(production orders) / var(retailer orders) (Lee, Padmanabhan and Whang, 1997); 0 if orders never vary."""
    demand_var = float(np.var(np.asarray(orders_units, dtype=np.float64)))
    if demand_var <= 1e-12:
        return 0.0
    return float(np.var(np.asarray(production_units, dtype=np.float64)) / demand_var)


def max_drawdown(series: np.ndarray) -> float:
    values = np.asarray(series, dtype=np.float64)
    if values.size == 0:
        return 0.0
    return float(np.max(1.0 - values / np.maximum(np.maximum.accumulate(values), 1e-12)))


def fill_rate_variance(filled_units: np.ndarray, effective_units: np.ndarray) -> float:
    """Population variance over regions of filled / effective demand for the episode."""
    rates = np.asarray(filled_units, dtype=np.float64) / np.maximum(np.asarray(effective_units, dtype=np.float64), 1e-9)
    return float(np.var(rates)) if rates.size else 0.0


def supply_episode_metrics(steps: Mapping[str, list], region_totals: np.ndarray) -> dict[str, float]:
    """The :data:`SUPPLY_METRICS` of one episode from its step records and the regions' (filled, effective) totals."""
    s = {key: np.asarray(value, dtype=np.float64) for key, value in steps.items() if key not in ("day",)}
    actions = np.column_stack([s["supplier_incentive"], s["release_ratio"], s["demand_damping"]])
    jitter = float(np.mean(np.abs(np.diff(actions, axis=0)).sum(axis=1))) if len(actions) > 1 else 0.0
    totals = np.asarray(region_totals, dtype=np.float64).reshape(-1, 2)
    return {
        "cumulative_reward": float(np.sum(s["reward"])),
        "fill_volume_units": float(np.sum(s["filled_units"])),
        "revenue": float(np.sum(s["delivered_units"] * ORGYM_UNIT_PRICE * s["price_index"])),
        "violation_rate": float(np.mean(s["violation_rate"])),
        "phantom_backed_units": float(np.sum(s["unsafe_units"])),
        "phantom_fill_volume_units": float(np.sum(s["phantom_fill_volume_units"])),
        "max_price_drawdown": max_drawdown(s["price_index"]),
        "peak_backlog_units": float(np.max(s["backlog_units"])),
        "bullwhip_ratio": bullwhip_ratio(s["production_units"], s["orders_units"]),
        "action_jitter": jitter,
        "fill_rate_variance": fill_rate_variance(totals[:, 0], totals[:, 1]),
        "final_price_index": float(s["price_index"][-1]),
    }
