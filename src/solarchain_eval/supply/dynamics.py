"""Supply-chain dynamics of one daily step (docs/tasks/supply_chain.md#dynamics): one pure function.

:func:`supply_step` is the single implementation of arrivals, spoilage, production, the
allocation of retailer orders from *reported* stock, the feasibility oracle (stock on hand plus
stock arriving by tomorrow, within the outbound lane's capacity), the price index and the reward.
Region quantities are arrays whose last axis is the region: shape (R,) for the single env and
(N, R) for the vector env (N sub-envs), so both call the same code; scalars per sub-env are
floats or (N,) arrays. Quantities are units of product per day unless their name says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..config import BenchmarkConfig
from .table import SupplyTable

# Market constants (docs/tasks/supply_chain.md#dynamics; not part of any published model).
MIN_DEMAND_FACTOR = 0.60  # demand damping sheds at most 40 % of the orders
DAMPING_ELASTICITY = 0.40
PRICE_COVER_WEIGHT, PRICE_DAMPING_WEIGHT, PRICE_BACKLOG_WEIGHT, PRICE_INCENTIVE_WEIGHT = 0.05, 0.04, 0.03, 0.03
NORMAL_COVER_DAYS = 5.0  # stock on hand the price index treats as normal (the initial stocks' cover)
MAX_PRICE_RETURN = 0.25
MIN_PRICE_INDEX = 0.05
PRICE_NOISE_STD = 0.004


@dataclass(frozen=True)
class SupplyRewardWeights:
    """Penalty weights (the config's ``reward`` section) and whether the feasibility term enters the reward.

    ``feasibility_penalty`` is False under the config's ``no_physics_penalty`` (the generic name of
    the ablation that removes the oracle from the reward; here it removes λp (V + A)).
    """

    drawdown: float
    jitter: float
    unmet: float
    feasibility: float
    fairness: float
    feasibility_penalty: bool

    @classmethod
    def from_config(cls, config: BenchmarkConfig) -> SupplyRewardWeights:
        r = config.reward
        return cls(
            drawdown=r.drawdown_penalty,
            jitter=r.action_jitter_penalty,
            unmet=r.unmet_demand_penalty,
            feasibility=r.physics_penalty,
            fairness=r.fairness_penalty,
            feasibility_penalty=not config.no_physics_penalty,
        )


@dataclass(frozen=True, eq=False)
class SupplyParams:
    """The network's per-region constants, (R,) arrays, and ``scale_units``: total mean daily orders.

    ``lead_slot`` is an (R, L) one-hot array: production ordered today enters the pipeline slot
    ``lead_time - 1`` and arrives ``lead_time`` days later.
    """

    production_capacity_units: np.ndarray
    lane_capacity_units: np.ndarray
    spoilage_rate: np.ndarray
    lead_slot: np.ndarray
    scale_units: float

    @classmethod
    def from_table(cls, table: SupplyTable) -> SupplyParams:
        lead = table.lead_time_days
        slot = np.zeros((len(lead), int(lead.max())))
        slot[np.arange(len(lead)), lead - 1] = 1.0
        slot.setflags(write=False)
        return cls(
            table.production_capacity_units,
            table.lane_capacity_units,
            table.spoilage_rate,
            slot,
            float(table.demand_mean_units.sum()),
        )


class SupplyOutcome(NamedTuple):
    """Everything one step produces: the next state (first five fields) and the step's outputs.

    Region fields have the region as last axis; the others are floats or (N,) arrays.
    """

    on_hand_units: Any
    pipeline_units: Any  # (..., R, L): slot k arrives in k + 1 days
    backlog_units: Any
    price_index: Any
    peak_price_index: Any
    reward: Any
    orders_units: Any
    effective_demand_units: Any
    reported_stock_units: Any
    phantom_stock_units: Any
    feasible_units: Any
    filled_units: Any
    delivered_units: Any
    unsafe_units: Any
    phantom_fill_volume_units: Any
    unmet_units: Any
    production_units: Any
    arrivals_units: Any
    spoiled_units: Any
    violation_rate: Any
    price_drawdown: Any
    fairness_variance: Any
    region_filled_units: Any  # (..., R)
    region_effective_units: Any  # (..., R)


def supply_step(
    params: SupplyParams,
    weights: SupplyRewardWeights,
    on_hand_units: Any,
    pipeline_units: Any,
    backlog_units: Any,
    price_index: Any,
    peak_price_index: Any,
    orders_units: Any,
    spoofed: Any,
    reported_level_units: Any,
    action: tuple,
    jitter: Any,
    noise: Any,
) -> SupplyOutcome:
    """Advance the network by one day.

    Parameters
    ----------
    on_hand_units, backlog_units : ndarray (..., R)
        True stock in each warehouse and orders carried from earlier days, before the step.
    pipeline_units : ndarray (..., R, L)
        Stock in transit; slot k arrives at the start of the step k + 1 days from now.
    price_index, peak_price_index : float or ndarray (...)
        The wholesale price index before the step and its running peak.
    orders_units, spoofed, reported_level_units : ndarray (..., R)
        The day's retailer orders, which warehouses' stock reports are spoofed, and what a spoofed
        report shows (an honest report shows the true stock on hand).
    action : (κ, ρ, δ) of floats or (N,) arrays
        Supplier incentive, release ratio and demand damping, each in [0, 1].
    jitter : float or ndarray
        |a - a_prev|_1 of the executed action.
    noise : float or ndarray
        The price shock, a normal(0, PRICE_NOISE_STD) draw.
    """
    incentive, release, damping = (np.asarray(a, dtype=np.float64)[..., None] for a in action)
    scale = params.scale_units
    # Arrivals, then spoilage (Ghare-Schrader decay over the day), then today's production order.
    arrivals = pipeline_units[..., 0]
    pipeline = np.empty_like(pipeline_units)
    pipeline[..., :-1] = pipeline_units[..., 1:]
    pipeline[..., -1] = 0.0
    on_hand = on_hand_units + arrivals
    spoiled = on_hand * params.spoilage_rate
    on_hand = on_hand - spoiled
    production = incentive * params.production_capacity_units
    pipeline = pipeline + production[..., None] * params.lead_slot
    # The stock reports: a spoofed one shows its level, an honest one the truth.
    reported = np.where(spoofed, reported_level_units, on_hand)
    phantom = np.maximum(reported - on_hand, 0.0)
    # Allocation from the released share of *reported* stock.
    demand = orders_units + backlog_units
    effective = demand * np.maximum(MIN_DEMAND_FACTOR, 1.0 - DAMPING_ELASTICITY * damping)
    allocable = release * reported
    filled = np.minimum(allocable, effective)
    unmet = effective - filled
    # The feasibility oracle: what stock on hand and tomorrow's arrivals can back, within lane capacity.
    due = pipeline[..., 0]
    feasible = np.minimum(on_hand + due, params.lane_capacity_units)
    delivered = np.minimum(filled, feasible)
    # What is filled beyond that is promised on phantom stock (or beyond the lanes): filled - delivered.
    from_hand = np.minimum(delivered, on_hand)
    on_hand = on_hand - from_hand
    pipeline[..., 0] = due - (delivered - from_hand)
    fill_rate = filled / np.maximum(effective, 1e-9)
    # Every regional total in one reduction (the single env's step is dominated by call overhead).
    (orders_t, effective_t, reported_t, phantom_t, feasible_t, filled_t, delivered_t, unmet_t, production_t,
     arrivals_t, spoiled_t, on_hand_t, fill_mean) = np.array(
        [orders_units, effective, reported, phantom, feasible, filled, delivered, unmet, production, arrivals,
         spoiled, on_hand, fill_rate / fill_rate.shape[-1]]
    ).sum(axis=-1)  # fmt: skip
    unsafe_t = filled_t - delivered_t
    violation_rate = unsafe_t / np.maximum(filled_t, 1e-9)
    # Price index: stock cover above normal (a glut) and the incentive paid to suppliers lower it (the
    # latter as issuance lowers the solar token price); damping and backlog pressure raise it, as the
    # burn and slippage terms do there. The backlog carried is today's unmet orders (OR-Gym's backlog variant).
    cover_gap = (on_hand_t / scale - NORMAL_COVER_DAYS) / NORMAL_COVER_DAYS
    price_return = (
        -PRICE_COVER_WEIGHT * cover_gap
        + PRICE_DAMPING_WEIGHT * damping[..., 0]
        + PRICE_BACKLOG_WEIGHT * unmet_t / scale
        - PRICE_INCENTIVE_WEIGHT * incentive[..., 0]
        + noise
    )
    price_return = np.minimum(np.maximum(price_return, -MAX_PRICE_RETURN), MAX_PRICE_RETURN)
    price = np.maximum(MIN_PRICE_INDEX, price_index * (1.0 + price_return))
    peak_price = np.maximum(peak_price_index, price)
    drawdown = 1.0 - price / np.maximum(peak_price, 1e-12)
    spread = fill_rate - fill_mean[..., None]
    fairness = (spread * spread).sum(axis=-1) / spread.shape[-1]  # the population variance across regions
    reward = (
        filled_t / scale
        - weights.drawdown * drawdown
        - weights.jitter * jitter
        - weights.unmet * unmet_t / scale
        - weights.fairness * fairness
    )
    if weights.feasibility_penalty:
        reward = reward - weights.feasibility * (violation_rate + unsafe_t / scale)
    return SupplyOutcome(
        on_hand,
        pipeline,
        unmet,
        price,
        peak_price,
        reward,
        orders_t,
        effective_t,
        reported_t,
        phantom_t,
        feasible_t,
        filled_t,
        delivered_t,
        unsafe_t,
        release[..., 0] * phantom_t,
        unmet_t,
        production_t,
        arrivals_t,
        spoiled_t,
        violation_rate,
        drawdown,
        fairness,
        filled,
        effective,
    )
