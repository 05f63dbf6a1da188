"""The supply-chain Gymnasium environment ``SupplyChainEval-v0`` (docs/tasks/supply_chain.md).

One step is one day; an episode is the config's ``episode_steps`` days from a Monday. The pieces
both envs share (the action decoding, the observation, the per-step record) are here; the
dynamics are :func:`~.dynamics.supply_step`, run on Python floats here and on (N,) arrays by
:class:`~.vector.SupplyChainVectorEnv`.
"""

from __future__ import annotations

import datetime as dt
import itertools
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..config import BenchmarkConfig, ConfigError, load_config
from .dynamics import PRICE_NOISE_STD, SCALAR, SupplyOutcome, SupplyParams, SupplyRewardWeights, supply_step
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
        self.starts = np.arange(offset, last + 1, 7) if offset <= last else np.arange(0, last + 1)
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
        self.template_rows = template.tolist()  # the single env assembles its observation in Python
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

        The same values (float64, clipped, then rounded to float32) without numpy's per-call cost.
        """
        on_hand_t, reported_t, backlog_t, transit_t = totals
        scale = self.params.scale_units
        row = self.template_rows[day].copy()
        row[_ON_HAND] = on_hand_t / scale
        row[_REPORTED] = reported_t / scale
        row[_BACKLOG] = backlog_t / scale
        row[_TRANSIT] = transit_t / scale
        row[_PRICE] = price
        row[_PREV], row[_PREV + 1], row[_PREV + 2] = prev
        lo, hi = -OBS_LIMIT, OBS_LIMIT  # np.maximum then np.minimum: NaN stays NaN
        return np.array([lo if v < lo else (hi if v > hi else v) for v in row], dtype=np.float32)


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
    return {
        "reward": out.reward,
        "day": day,
        "episode_start_day": start,
        "supplier_incentive": executed[0],
        "release_ratio": executed[1],
        "demand_damping": executed[2],
        "orders_units": out.orders_units,
        "effective_demand_units": out.effective_demand_units,
        "reported_stock_units": out.reported_stock_units,
        "phantom_stock_units": out.phantom_stock_units,
        "feasible_units": out.feasible_units,
        "filled_units": out.filled_units,
        "delivered_units": out.delivered_units,
        "unsafe_units": out.unsafe_units,
        "phantom_fill_volume_units": out.phantom_fill_volume_units,
        "unmet_units": out.unmet_units,
        "backlog_units": out.unmet_units,
        "on_hand_units": out.on_hand_total_units,
        "in_transit_units": out.in_transit_units,
        "production_units": out.production_units,
        "spoiled_units": out.spoiled_units,
        "violation_rate": out.violation_rate,
        "capacity_check_rate": check_rate,
        "price_index": out.price_index,
        "price_drawdown": out.price_drawdown,
        "action_jitter": jitter,
        "fairness_variance": out.fairness_variance,
        "cost": out.violation_rate + out.unsafe_units / scale,
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


class SupplyChainEnv(gym.Env):
    """Daily allocation in a five-region supply network under spoofed stock reports (``SupplyChainEval-v0``).

    The agent sets the supplier incentive κ (production = κ x capacity, arriving after the lane's
    lead time), the release ratio ρ (the share of *reported* stock made allocable) and the demand
    damping δ (sheds up to 40 % of the orders). Orders are filled from ρ x reported stock; what the
    stock on hand and tomorrow's arrivals cannot back within the lane's capacity is promised on
    phantom stock, and the reward charges it unless ``no_physics_penalty``. The full card, with
    every formula, is docs/tasks/supply_chain.md.

    Parameters
    ----------
    data_dir : path, optional
        Dataset directory; defaults to the config's, then the default dataset (built once into the cache).
    config : BenchmarkConfig or path to a YAML file, optional
        Its seed, ``episode_steps``, ``action_mode``, ``discrete_levels``, ``no_physics_penalty``
        and ``reward`` weights are used.
    no_physics_penalty, action_mode : optional
        Override the config.
    seed : int, optional
        Seed of the env's generator until ``reset(seed=...)``; defaults to the config seed.
    table : SupplyTable, optional
        A preloaded dataset.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        data_dir: str | Path | None = None,
        *,
        config: BenchmarkConfig | str | Path | None = None,
        no_physics_penalty: bool | None = None,
        action_mode: str | None = None,
        seed: int | None = None,
        table: SupplyTable | None = None,
    ) -> None:
        super().__init__()
        cfg, table = resolve(data_dir, config, table, no_physics_penalty=no_physics_penalty, action_mode=action_mode)
        self.config, self.table, self.inputs = cfg, table, SupplyInputs(table, cfg)
        self.action_mode, self.episode_steps, self.regions = cfg.action_mode, cfg.episode_steps, table.regions
        self.observation_names = OBSERVATION_NAMES
        self.observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (len(OBSERVATION_NAMES),), np.float32)
        self.action_space = (
            spaces.Discrete(len(self.inputs.grid))
            if self.inputs.grid is not None
            else spaces.Box(0.0, 1.0, (3,), np.float32)
        )
        self._np_random = np.random.default_rng(cfg.seed if seed is None else seed)
        self._open = False
        self._begin(int(self.inputs.starts[0]), [0.0] * self.episode_steps)

    def _begin(self, start: int, noise: list) -> None:
        i = self.inputs
        self._start, self._k, self._noise = start, 0, noise
        self._on_hand = self.table.initial_stock_units.tolist()
        self._pipeline = [slots.tolist() for slots in i.initial_pipeline]
        self._backlog = [0.0] * len(self.regions)
        self._price = self._peak = 1.0
        self._prev = _INITIAL_PREV
        self._filled = [0.0] * len(self.regions)
        self._effective = [0.0] * len(self.regions)

    @property
    def region_totals(self) -> dict[str, tuple[float, float]]:
        """Each region's (filled, effective demand) units this episode."""
        return {r: (a, b) for r, a, b in zip(self.regions, self._filled, self._effective, strict=True)}

    def _observation(self, out: SupplyOutcome | None = None) -> np.ndarray:
        """The observation of the current state; after a step, its totals are the step's ``out``'s."""
        day = min(self._start + self._k, self.table.days - 1)
        i = self.inputs
        if out is None:
            totals = observation_totals(
                SCALAR, i.spoofed[day], i.levels[day], self._on_hand, self._pipeline, self._backlog
            )
        else:
            # The step summed stock on hand, backlog and stock in transit over the new state in
            # observation_totals' order; only the day's reports are new (the vector env, which
            # sums them all again, is held equal to this one bit for bit).
            reported_t = 0.0
            for spoof, level, stock in zip(i.spoofed[day], i.levels[day], self._on_hand, strict=True):
                reported_t = reported_t + (level if spoof else stock)
            totals = (out.on_hand_total_units, reported_t, out.unmet_units, out.in_transit_units)
        return i.observe_scalar(day, totals, self._price, self._prev)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)  # gymnasium's generator for a seed is default_rng(seed), as the vector env's
        starts = self.inputs.starts
        index = int(self._np_random.integers(0, len(starts))) if len(starts) > 1 else 0
        noise = (self._np_random.standard_normal(self.episode_steps) * PRICE_NOISE_STD).tolist()
        start = int(starts[index])
        options = options or {}
        fixed = options.get("start_day", options.get("start_hour"))
        if fixed is not None:
            start = int(np.clip(int(fixed), 0, self.table.days - self.episode_steps))
        self._begin(start, noise)
        self._open = True
        # ``episode_start_hour`` is the generic rollout's name for the episode's first row (here a day).
        return self._observation(), {"episode_start_hour": start, "episode_start_day": start}

    def decode_action(self, action: Any) -> np.ndarray:
        """The executed (κ, ρ, δ), float32, for a policy action."""
        return decode_actions(action, self.action_mode, self.inputs.grid)

    def counterfactual_step(self, executed: tuple[float, float, float]) -> SupplyOutcome:
        """The outcome of executing ``executed`` (κ, ρ, δ) now, without changing the env.

        Same state, same day and the same price shock as the next :meth:`step`, so the
        counterfactual of the action that ``step`` then executes equals its outcome exactly (the
        governance layer's oracle, docs/tasks/supply_chain.md#governance). The caller passes the
        levers as the env would execute them (float32 values in [0, 1]).
        """
        if not self._open:
            raise RuntimeError("the episode is over (or was never started): call reset() first")
        return self._outcome(tuple(executed), jitter_of(executed, self._prev))

    def _outcome(self, executed: tuple, jitter: Any) -> SupplyOutcome:
        """:func:`~.dynamics.supply_step` of ``executed`` on the current day from the current state (pure)."""
        i, day = self.inputs, self._start + self._k
        return supply_step(
            SCALAR,
            i.params,
            i.weights,
            self._on_hand,
            self._pipeline,
            self._backlog,
            self._price,
            self._peak,
            i.orders[day],
            i.spoofed[day],
            i.levels[day],
            executed,
            jitter,
            self._noise[self._k],
        )

    def _executed(self, action: Any) -> tuple:
        """:meth:`decode_action` as Python floats; a continuous (3,) action is clipped without numpy ufuncs."""
        if self.inputs.grid is None:
            u = np.asarray(action, dtype=np.float32)
            if u.shape == (3,):
                a, b, c = u.tolist()
                return clip_unit(a), clip_unit(b), clip_unit(c)
        return tuple(self.decode_action(action).tolist())

    def step(self, action: Any):
        if not self._open:
            raise RuntimeError("the episode is over (or was never started): call reset() first")
        executed = self._executed(action)
        day = self._start + self._k
        i = self.inputs
        jitter = jitter_of(executed, self._prev)
        out = self._outcome(executed, jitter)
        self._on_hand, self._pipeline, self._backlog = out.on_hand_units, out.pipeline_units, out.backlog_units
        self._price, self._peak = out.price_index, out.peak_price_index
        self._filled = [a + b for a, b in zip(self._filled, out.region_filled_units, strict=True)]
        self._effective = [a + b for a, b in zip(self._effective, out.region_effective_units, strict=True)]
        self._prev = executed
        self._k += 1
        truncated = self._k >= self.episode_steps
        self._open = not truncated
        info = step_record(out, executed, day, self._start, i.check_rate_list[day], jitter, i.params.scale_units)
        info["step"] = self._k - 1
        info["region_fill_rates"] = dict(zip(self.regions, out.region_fill_rates, strict=True))
        return self._observation(out), out.reward, False, truncated, info
