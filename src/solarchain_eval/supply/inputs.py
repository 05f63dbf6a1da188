"""The pieces the supply-chain environments share (docs/tasks/supply_chain.md).

The observation's and the per-step record's layout, the action decoding, a dataset's constants
as the envs use them (:class:`SupplyInputs`) and the construction arguments' resolution: used
by the single env (:mod:`~.env`), the vector env (:mod:`~.vector`) and the JAX twin
(:mod:`~.jax_env`), so the three read one definition of each.
"""

from __future__ import annotations

import datetime as dt
import itertools
from pathlib import Path
from typing import Any

import numpy as np

from ..config import BenchmarkConfig, ConfigError, load_config, select_starts
from .dynamics import SupplyOutcome, SupplyParams, SupplyRewardWeights
from .table import SupplyTable, default_supply_dir, load_supply_table

ENV_ID = "SupplyChainEval-v0"
OBS_LIMIT = 10.0
OBSERVATION_NAMES = (
    "day_of_week_sin",
    "day_of_week_cos",
    "on_hand_days",  # true stock on hand, in days of mean network demand
    "reported_stock_days",  # the day's stock reports (spoofed ones included)
    "in_transit_days",
    "orders_days",  # today's retailer orders
    "backlog_days",
    "price_index",
    "capacity_check_rate",  # share of regions whose report exceeds the warehouse capacity
    "warehouse_capacity_days",
    "production_capacity_days",
    "mean_lead_time_weeks",
    "prev_supplier_incentive",
    "prev_release_ratio",
    "prev_demand_damping",
)
OBS = {name: i for i, name in enumerate(OBSERVATION_NAMES)}
_ON_HAND, _REPORTED, _TRANSIT, _BACKLOG, _PRICE = (
    OBS[n] for n in ("on_hand_days", "reported_stock_days", "in_transit_days", "backlog_days", "price_index")
)
_PREV = OBS["prev_supplier_incentive"]
LEVER_NAMES = ("supplier_incentive", "release_ratio", "demand_damping")
#: The previous action of an episode's first step (the static baseline's action).
INITIAL_ACTION = (0.25, 0.75, 0.05)
#: Per-step quantities in ``info`` (the ``actions.csv`` columns of a run); units in their names.
STEP_FIELDS = (
    "reward",
    "day",
    "episode_start_day",
    *LEVER_NAMES,
    "orders_units",
    "effective_demand_units",
    "reported_stock_units",
    "phantom_stock_units",
    "feasible_units",
    "filled_units",
    "delivered_units",
    "unsafe_units",
    "phantom_fill_volume_units",
    "unmet_units",
    "backlog_units",
    "on_hand_units",
    "in_transit_units",
    "production_units",
    "spoiled_units",
    "violation_rate",
    "capacity_check_rate",
    "price_index",
    "price_drawdown",
    "action_jitter",
    "fairness_variance",
    "cost",
)


#: INITIAL_ACTION as the executed (float32-valued) levers of the single env.
_INITIAL_PREV = tuple(np.array(INITIAL_ACTION, dtype=np.float32).tolist())


def decode_actions(action: Any, action_mode: str, grid: np.ndarray | None) -> np.ndarray:
    """Executed levers, float32 (..., 3): NaN -> 0, clipped to [0, 1]; a discrete index picks a grid point."""
    if action_mode == "discrete":
        return grid[np.asarray(action, dtype=np.int64)]
    u = np.asarray(action, dtype=np.float32)
    if u.shape[-1:] != (3,):
        raise ValueError(f"a continuous action has 3 components, got shape {u.shape}")
    return np.fmin(np.fmax(u, np.float32(0.0)), np.float32(1.0))  # fmax takes NaN to 0


def action_grid(levels: int) -> np.ndarray:
    """The discrete actions: {0, 1/(levels-1), ..., 1}^3 in ``itertools.product`` order, float32."""
    values = np.linspace(0.0, 1.0, levels, dtype=np.float32)
    return np.array(list(itertools.product(values, repeat=3)), dtype=np.float32)


class SupplyInputs:
    """A table's constants as the envs use them (built once per env)."""

    def __init__(self, table: SupplyTable, config: BenchmarkConfig) -> None:
        if config.episode_steps > table.days:
            raise ConfigError(
                f"episode_steps = {config.episode_steps} is longer than {table.source}, which has {table.days} days"
            )
        self.table, self.params = table, SupplyParams.from_table(table)
        self.weights = SupplyRewardWeights.from_config(config)
        self.steps = config.episode_steps
        first = dt.date.fromisoformat(table.dates[0])
        # Episodes start on Mondays with a whole episode after them (every day if there is no Monday).
        offset = (7 - first.weekday()) % 7
        last = table.days - self.steps
        starts = np.arange(offset, last + 1, 7) if offset <= last else np.arange(0, last + 1)
        self.starts = select_starts(starts, config.start_days, 1, str(table.source))
        weekday = (first.weekday() + np.arange(table.days)) % 7
        self.check_rate = table.capacity_check_rate
        self.check_rate_list = self.check_rate.tolist()
        scale = self.params.scale_units
        # The day's features that do not depend on the state, one row per day; the rest is filled per step.
        template = np.zeros((table.days, len(OBSERVATION_NAMES)))
        template[:, OBS["day_of_week_sin"]] = np.sin(2 * np.pi * weekday / 7)
        template[:, OBS["day_of_week_cos"]] = np.cos(2 * np.pi * weekday / 7)
        template[:, OBS["orders_days"]] = table.orders_units.sum(axis=1) / scale
        template[:, OBS["capacity_check_rate"]] = self.check_rate
        template[:, OBS["warehouse_capacity_days"]] = table.warehouse_capacity_units.sum() / scale
        template[:, OBS["production_capacity_days"]] = table.production_capacity_units.sum() / scale
        lead_weeks = float(np.average(table.lead_time_days, weights=table.demand_mean_units)) / 7.0
        template[:, OBS["mean_lead_time_weeks"]] = lead_weeks
        template.setflags(write=False)
        self.template = template
        # The single env assembles its observation in Python from these rows, clipped once here (a clip
        # is per element, so clipping the constant features up front changes no observation).
        self.template_rows = np.minimum(np.maximum(template, -OBS_LIMIT), OBS_LIMIT).tolist()
        # In steady flow every pipeline slot before the lead time carries a day of mean demand. A region
        # holds only its lead time's slots: production enters the last of them, so later ones stay empty.
        self.initial_pipeline = tuple(
            np.full(lead, mean) for lead, mean in zip(self.params.lead_time_days, table.demand_mean_units, strict=True)
        )
        self.grid = action_grid(config.discrete_levels) if config.action_mode == "discrete" else None
        # The day's inputs per region: Python lists for the single env, region-major arrays for gathers.
        self.orders = table.orders_units.tolist()
        self.spoofed = table.spoofed.tolist()
        self.levels = table.reported_level_units.tolist()
        self.orders_by_region = np.ascontiguousarray(table.orders_units.T)
        self.spoofed_by_region = np.ascontiguousarray(table.spoofed.T)
        self.levels_by_region = np.ascontiguousarray(table.reported_level_units.T)

    def observe(
        self,
        ops: Any,
        day: Any,
        spoofed: list,
        levels: list,
        on_hand: list,
        pipeline: list,
        backlog: list,
        price: Any,
        prev: Any,
    ) -> np.ndarray:
        """The observation(s) at the start of ``day`` (an int, or an (N,) array with per-env arrays).

        ``spoofed`` and ``levels`` are the day's reports per region (see :func:`observation_totals`).
        """
        on_hand_t, reported_t, backlog_t, transit_t = observation_totals(
            ops, spoofed, levels, on_hand, pipeline, backlog
        )
        scale = self.params.scale_units
        obs = self.template[day].copy()
        obs[..., _ON_HAND] = on_hand_t / scale
        obs[..., _REPORTED] = reported_t / scale
        obs[..., _BACKLOG] = backlog_t / scale
        obs[..., _TRANSIT] = transit_t / scale
        obs[..., _PRICE] = price
        obs[..., _PREV:] = prev
        return np.minimum(np.maximum(obs, -OBS_LIMIT), OBS_LIMIT).astype(np.float32)

    def observe_scalar(self, day: int, totals: tuple, price: float, prev: tuple) -> np.ndarray:
        """:meth:`observe` for one env from its :func:`observation_totals`, assembled on Python floats.

        The same values (float64, clipped, then rounded to float32) without numpy's per-call cost:
        the day's constant features come pre-clipped, the previous levers are executed ones (in
        [0, 1] already), so only the five state features are clipped here.
        """
        on_hand_t, reported_t, backlog_t, transit_t = totals
        scale = self.params.scale_units
        lo, hi = -OBS_LIMIT, OBS_LIMIT  # np.maximum then np.minimum: NaN stays NaN
        v = on_hand_t / scale
        on_hand = lo if v < lo else (hi if v > hi else v)
        v = reported_t / scale
        reported = lo if v < lo else (hi if v > hi else v)
        v = transit_t / scale
        transit = lo if v < lo else (hi if v > hi else v)
        v = backlog_t / scale
        backlog = lo if v < lo else (hi if v > hi else v)
        v = price
        price = lo if v < lo else (hi if v > hi else v)
        r = self.template_rows[day]
        # OBSERVATION_NAMES' order; observe writes by name and the vector env's observations are held
        # equal to this env's bit for bit (tests/test_supply_env.py)
        return np.array(
            (r[0], r[1], on_hand, reported, transit, r[5], backlog, price, r[8], r[9], r[10], r[11], *prev),
            dtype=np.float32,
        )


def observation_totals(ops: Any, spoofed: list, levels: list, on_hand: list, pipeline: list, backlog: list) -> tuple:
    """Network totals the observation shows: (on hand, reported, backlog, in transit) units.

    Summed over regions left to right, the same operations on floats, numpy arrays and JAX values.
    """
    on_hand_t = reported_t = backlog_t = transit_t = 0.0
    for r, stock in enumerate(on_hand):
        on_hand_t = on_hand_t + stock
        reported_t = reported_t + ops.where(spoofed[r], levels[r], stock)
        backlog_t = backlog_t + backlog[r]
        for slot in pipeline[r]:
            transit_t = transit_t + slot
    return on_hand_t, reported_t, backlog_t, transit_t


def clip_unit(x: float) -> float:
    """``np.fmin(np.fmax(x, 0), 1)`` on a Python float: NaN -> 0, -0.0 -> 0.0, ±inf -> 0 or 1."""
    x = x if x > 0.0 else 0.0
    return x if x < 1.0 else 1.0


def jitter_of(executed: tuple, previous: tuple) -> Any:
    """|a - a_prev|_1 of float32-valued levers, in float64 (floats or (N,) arrays)."""
    return abs(executed[0] - previous[0]) + abs(executed[1] - previous[1]) + abs(executed[2] - previous[2])


def step_record(
    out: SupplyOutcome, executed: tuple, day: Any, start: Any, check_rate: Any, jitter: Any, scale: float
) -> dict:
    """The :data:`STEP_FIELDS` of one step (floats, or (N,) arrays for the vector env); ``cost`` is the
    feasibility term V + A (A in days of mean network demand) for safe-RL algorithms."""
    # One unpacking instead of an attribute read per field (the single env's per-step cost).
    (
        _,
        _,
        _,
        price,
        _,
        reward,
        orders,
        effective,
        reported,
        phantom,
        feasible,
        filled,
        delivered,
        unsafe,
        phantom_fill,
        unmet,
        production,
        _,
        spoiled,
        on_hand,
        transit,
        violation,
        drawdown,
        fairness,
        _,
        _,
        _,
    ) = out  # SupplyOutcome's field order
    return {
        "reward": reward,
        "day": day,
        "episode_start_day": start,
        "supplier_incentive": executed[0],
        "release_ratio": executed[1],
        "demand_damping": executed[2],
        "orders_units": orders,
        "effective_demand_units": effective,
        "reported_stock_units": reported,
        "phantom_stock_units": phantom,
        "feasible_units": feasible,
        "filled_units": filled,
        "delivered_units": delivered,
        "unsafe_units": unsafe,
        "phantom_fill_volume_units": phantom_fill,
        "unmet_units": unmet,
        "backlog_units": unmet,
        "on_hand_units": on_hand,
        "in_transit_units": transit,
        "production_units": production,
        "spoiled_units": spoiled,
        "violation_rate": violation,
        "capacity_check_rate": check_rate,
        "price_index": price,
        "price_drawdown": drawdown,
        "action_jitter": jitter,
        "fairness_variance": fairness,
        "cost": violation + unsafe / scale,
    }


def resolve(
    data_dir: str | Path | None, config: BenchmarkConfig | str | Path | None, table: SupplyTable | None, **updates: Any
) -> tuple[BenchmarkConfig, SupplyTable]:
    """The config (``config`` with the constructor's overrides) and the table an env runs on."""
    cfg = config if isinstance(config, BenchmarkConfig) else load_config(config) if config else BenchmarkConfig()
    if updates.get("action_mode") not in (None, "continuous", "discrete"):
        raise ValueError(f"unknown action_mode {updates['action_mode']!r} (continuous or discrete)")
    cfg = cfg.with_updates(**updates)
    if table is None:
        table = load_supply_table(data_dir or cfg.data_dir or default_supply_dir())
    return cfg, table
