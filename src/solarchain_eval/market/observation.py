"""Observation layout (docs/environment.md#observation-space) and the per-hour template it is built from."""

from __future__ import annotations

import numpy as np

from .dynamics import MarketHours

OBSERVATION_NAMES = (
    "hour_sin",
    "hour_cos",
    "verified_supply_MWh",
    "reported_supply_MWh",
    "pmax_MWh",
    "supply_gap",
    "liquidity",
    "token_price",
    "raw_physics_record_rate",
    "static_slippage",
    "prev_reward_ratio",
    "prev_liquidity_ratio",
)
OBS_LIQUIDITY, OBS_PRICE, OBS_PREV_ALPHA, OBS_PREV_ELL = 6, 7, 10, 11
OBS_GAP, OBS_VIOLATION, OBS_SLIPPAGE = 5, 8, 9
OBS_LIMIT = 10.0
#: Shape of one observation: one float32 per name in :data:`OBSERVATION_NAMES`.
OBSERVATION_SHAPE = (len(OBSERVATION_NAMES),)


def observation_template(hours: MarketHours) -> np.ndarray:
    """(H, 12) float32 rows with the hour's exogenous features; state columns are zero."""
    t = hours.table
    hour_of_day = np.arange(t.hours) % 24
    angle = 2 * np.pi * hour_of_day / 24
    rows = np.zeros((t.hours, len(OBSERVATION_NAMES)), dtype=np.float64)
    rows[:, 0] = np.sin(angle)
    rows[:, 1] = np.cos(angle)
    rows[:, 2] = t.verified_mwh
    rows[:, 3] = t.reported_mwh
    rows[:, 4] = t.pmax_mwh
    rows[:, OBS_GAP] = hours.supply_gap
    rows[:, OBS_VIOLATION] = t.raw_violation_rate
    rows[:, OBS_SLIPPAGE] = t.static_slippage
    template = np.clip(rows.astype(np.float32), -OBS_LIMIT, OBS_LIMIT)
    template.setflags(write=False)
    return template
