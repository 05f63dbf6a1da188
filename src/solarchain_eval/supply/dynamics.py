"""Supply-chain dynamics of one daily step (docs/tasks/supply_chain.md#dynamics): one pure function.

:func:`supply_step` is the single implementation of arrivals, spoilage, production, the
allocation of retailer orders from *reported* stock, the feasibility oracle (stock on hand plus
stock arriving by tomorrow, within the outbound lane's capacity), the price index and the reward.
It is written per region against an arithmetic back-end, as the solar market's ``market_step``
is: :data:`SCALAR` runs it on Python floats (the single env, through a copy specialised for floats,
:class:`~.scalar.ScalarSupplyStep`, held equal to it bit for bit: a change here is made there too),
:class:`BatchOps` on (N,) float64 arrays, one element per sub-env (the vector env), and
:class:`~.jax_env.SupplyJaxOps` on JAX values (the JAX twin). A region
quantity is a list with one such value per region (regions in the table's order); both back-ends
evaluate the same IEEE double operations in the same order (sums left to right over regions), so
a sub-env of the vector env reproduces the single env bit for bit. Quantities are units of
product per day unless their name says otherwise.
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


def _minimum(a: float, b: float) -> float:
    return b if b < a else a  # builtin min(a, b) (it keeps a unless b < a), at a third of its call cost


def _maximum(a: float, b: float) -> float:
    return b if b > a else a  # builtin max(a, b)


class ScalarOps:
    """Python-float back-end (one env)."""

    minimum = staticmethod(_minimum)
    maximum = staticmethod(_maximum)
    zero = 0.0

    @staticmethod
    def where(condition: Any, if_true: Any, if_false: Any) -> Any:
        return if_true if condition else if_false


class BatchOps:
    """numpy back-end: every per-env value is an (N,) float64 array."""

    minimum = staticmethod(np.minimum)
    maximum = staticmethod(np.maximum)
    where = staticmethod(np.where)

    def __init__(self, num_envs: int) -> None:
        self.zero = np.zeros(num_envs)
        self.zero.setflags(write=False)  # shared by every empty pipeline slot; never written


SCALAR = ScalarOps()


@dataclass(frozen=True, eq=False)
class SupplyParams:
    """The network's per-region constants (lists of Python floats) and ``scale_units``: total mean daily orders.

    Production ordered today enters pipeline slot ``lead_time - 1`` and arrives ``lead_time`` days later.
    """

    production_capacity_units: list
    lane_capacity_units: list
    spoilage_rate: list
    lead_time_days: list
    scale_units: float

    @classmethod
    def from_table(cls, table: SupplyTable) -> SupplyParams:
        return cls(
            table.production_capacity_units.tolist(),
            table.lane_capacity_units.tolist(),
            table.spoilage_rate.tolist(),
            [int(x) for x in table.lead_time_days],
            float(table.demand_mean_units.sum()),
        )

    @property
    def pipeline_slots(self) -> int:
        return max(self.lead_time_days)


class SupplyOutcome(NamedTuple):
    """Everything one step produces: the next state (first five fields) and the step's outputs.

    ``on_hand_units``, ``backlog_units``, ``region_filled_units``, ``region_effective_units`` and
    ``region_fill_rates`` (filled / effective demand) are lists over regions, ``pipeline_units`` a list over regions of lists over slots (slot k arrives
    in k + 1 days); every other field is one per-env value.
    """

    on_hand_units: list
    pipeline_units: list
    backlog_units: list
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
    on_hand_total_units: Any
    in_transit_units: Any
    violation_rate: Any
    price_drawdown: Any
    fairness_variance: Any
    region_filled_units: list
    region_effective_units: list
    region_fill_rates: list


def supply_step(
    ops: Any,
    params: SupplyParams,
    weights: SupplyRewardWeights,
    on_hand_units: list,
    pipeline_units: list,
    backlog_units: list,
    price_index: Any,
    peak_price_index: Any,
    orders_units: list,
    spoofed: list,
    reported_level_units: list,
    action: tuple,
    jitter: Any,
    noise: Any,
) -> SupplyOutcome:
    """Advance the network by one day.

    Parameters
    ----------
    ops : ScalarOps or BatchOps
        Arithmetic back-end (:data:`SCALAR` or a :class:`BatchOps`).
    on_hand_units, backlog_units : list over regions
        True stock in each warehouse and orders carried from earlier days, before the step.
    pipeline_units : list over regions of lists over slots
        Stock in transit; slot k arrives at the start of the step k + 1 days from now. A region
        needs at least its lead time's slots; the envs keep exactly those (production enters the
        last of them, so any later slot would stay empty).
    price_index, peak_price_index : float or ndarray
        The wholesale price index before the step and its running peak.
    orders_units, spoofed, reported_level_units : lists over regions
        The day's retailer orders, which warehouses' stock reports are spoofed, and what a spoofed
        report shows (an honest report shows the true stock on hand).
    action : (κ, ρ, δ) of floats or (N,) arrays
        Supplier incentive, release ratio and demand damping, each in [0, 1].
    jitter : float or ndarray
        |a - a_prev|_1 of the executed action.
    noise : float or ndarray
        The price shock, a normal(0, PRICE_NOISE_STD) draw.
    """
    incentive, release, damping = action
    minimum, maximum, where, zero = ops.minimum, ops.maximum, ops.where, ops.zero  # locals: the scalar env's hot loop
    damp = maximum(MIN_DEMAND_FACTOR, 1.0 - DAMPING_ELASTICITY * damping)
    p = params
    on_hand_next, pipeline_next, backlog_next, region_filled, region_effective, region_rate = [], [], [], [], [], []
    orders_t = effective_t = reported_t = phantom_t = feasible_t = filled_t = delivered_t = 0.0
    unmet_t = production_t = arrivals_t = spoiled_t = on_hand_t = transit_t = 0.0
    regions = zip(
        on_hand_units,
        pipeline_units,
        backlog_units,
        orders_units,
        spoofed,
        reported_level_units,
        p.spoilage_rate,
        p.production_capacity_units,
        p.lead_time_days,
        p.lane_capacity_units,
        strict=True,
    )
    for on_hand, slots, backlog, orders, spoof, level, spoilage, capacity, lead, lane in regions:
        # Arrivals, then spoilage (Ghare-Schrader decay over the day), then today's production order.
        arrivals = slots[0]
        slots = [*slots[1:], zero]
        stock = on_hand + arrivals
        spoiled = stock * spoilage
        stock = stock - spoiled
        production = incentive * capacity
        slots[lead - 1] = slots[lead - 1] + production
        # The stock report: a spoofed one shows its level, an honest one the truth.
        reported = where(spoof, level, stock)
        phantom = maximum(reported - stock, 0.0)
        # Allocation from the released share of *reported* stock; what is not filled is carried
        # as tomorrow's backlog (OR-Gym's backlog variant).
        effective = (orders + backlog) * damp
        filled = minimum(release * reported, effective)
        unmet = effective - filled
        # The feasibility oracle: stock on hand and tomorrow's arrivals, within the lane's capacity.
        # What is filled beyond that is promised on phantom stock (or beyond the lanes).
        due = slots[0]
        feasible = minimum(stock + due, lane)
        delivered = minimum(filled, feasible)
        from_hand = minimum(delivered, stock)
        stock = stock - from_hand
        slots[0] = due - (delivered - from_hand)
        on_hand_next.append(stock)
        pipeline_next.append(slots)
        backlog_next.append(unmet)
        region_filled.append(filled)
        region_effective.append(effective)
        region_rate.append(filled / maximum(effective, 1e-9))
        orders_t = orders_t + orders
        effective_t = effective_t + effective
        reported_t = reported_t + reported
        phantom_t = phantom_t + phantom
        feasible_t = feasible_t + feasible
        filled_t = filled_t + filled
        delivered_t = delivered_t + delivered
        unmet_t = unmet_t + unmet
        production_t = production_t + production
        arrivals_t = arrivals_t + arrivals
        spoiled_t = spoiled_t + spoiled
        on_hand_t = on_hand_t + stock
        for slot in slots:
            transit_t = transit_t + slot
    n = len(region_rate)
    mean_rate = 0.0
    for rate in region_rate:
        mean_rate = mean_rate + rate
    mean_rate = mean_rate / n
    fairness = 0.0
    for rate in region_rate:
        fairness = fairness + (rate - mean_rate) * (rate - mean_rate)
    fairness = fairness / n  # the population variance of the regions' fill rates
    unsafe_t = filled_t - delivered_t
    scale = p.scale_units
    violation_rate = unsafe_t / maximum(filled_t, 1e-9)
    # Price index: stock cover above normal (a glut) and the incentive paid to suppliers lower it (the
    # latter as issuance lowers the solar token price); damping and backlog pressure raise it, as the
    # burn and slippage terms do there.
    cover_gap = (on_hand_t / scale - NORMAL_COVER_DAYS) / NORMAL_COVER_DAYS
    price_return = (
        -PRICE_COVER_WEIGHT * cover_gap
        + PRICE_DAMPING_WEIGHT * damping
        + PRICE_BACKLOG_WEIGHT * unmet_t / scale
        - PRICE_INCENTIVE_WEIGHT * incentive
        + noise
    )
    price_return = minimum(maximum(price_return, -MAX_PRICE_RETURN), MAX_PRICE_RETURN)
    price = maximum(MIN_PRICE_INDEX, price_index * (1.0 + price_return))
    peak_price = maximum(peak_price_index, price)
    drawdown = 1.0 - price / maximum(peak_price, 1e-12)
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
        on_hand_next,
        pipeline_next,
        backlog_next,
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
        release * phantom_t,
        unmet_t,
        production_t,
        arrivals_t,
        spoiled_t,
        on_hand_t,
        transit_t,
        violation_rate,
        drawdown,
        fairness,
        region_filled,
        region_effective,
        region_rate,
    )
