"""Market dynamics of one hourly step (docs/environment.md#rewards): a pure function over floats or arrays.

:func:`market_step` is the single implementation of the physics gate, market clearing, token
price, city rewards and reward. The single env calls it with Python floats, the vector env
with float64 arrays (one element per sub-env), and the tests with either. Expressions keep
the original release's order of operations, so results agree with it bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..config import BenchmarkConfig
from ..data.table import HourlyTable

# Market constants (docs/environment.md#rewards; not part of the paper's configuration). The
# price shock's standard deviation lives with the draws that use it: episodes.PRICE_NOISE_STD.
MIN_DEMAND_FACTOR = 0.75  # token burning can cut effective demand by at most 25 %
BURN_DEMAND_ELASTICITY = 0.80
SLIPPAGE_DEPTH_OFFSET_MWH = 0.05
PRICE_GAP_WEIGHT, PRICE_VOLUME_WEIGHT, PRICE_BURN_WEIGHT = 0.04, 0.03, 0.10
PRICE_SLIPPAGE_WEIGHT, PRICE_ISSUANCE_WEIGHT = 0.08, 0.02
MAX_PRICE_RETURN = 0.35
MIN_TOKEN_PRICE = 0.05
LIQUIDITY_SHARE_WEIGHT = 0.01
FALLBACK_MIN_DEMAND_MWH = 0.001


@dataclass(frozen=True)
class RewardWeights:
    """Penalty weights and whether the physics term enters the reward."""

    drawdown: float
    jitter: float
    unmet: float
    physics: float
    fairness: float
    physics_penalty: bool
    max_total_allocation: float

    @classmethod
    def from_config(cls, config: BenchmarkConfig, no_physics_penalty: bool | None = None) -> RewardWeights:
        off = config.no_physics_penalty if no_physics_penalty is None else no_physics_penalty
        r = config.reward
        return cls(
            drawdown=r.drawdown_penalty,
            jitter=r.action_jitter_penalty,
            unmet=r.unmet_demand_penalty,
            physics=r.physics_penalty,
            fairness=r.fairness_penalty,
            physics_penalty=not off,
            max_total_allocation=config.market.max_total_allocation,
        )


@dataclass(frozen=True, eq=False)
class MarketHours:
    """Per-hour inputs of the dynamics, derived once from an :class:`HourlyTable`.

    ``unsafe_supply_mwh`` is X = max(rejected, excess, max(G_r - P_max, 0));
    ``clearing_demand_mwh`` is Q, or max(total verified MW, 0.001) in hours without trades;
    ``supply_gap`` is the observation's (G_v - Q) / max(Q, 1e-6) with the raw trade demand;
    ``city_share`` is each city's share of verified power and ``city_trust`` = 1 - its
    violation rate.
    """

    table: HourlyTable
    unsafe_supply_mwh: np.ndarray
    clearing_demand_mwh: np.ndarray
    supply_gap: np.ndarray
    city_share: np.ndarray
    city_trust: np.ndarray

    @classmethod
    def from_table(cls, table: HourlyTable) -> MarketHours:
        t = table
        unsafe = np.maximum(np.maximum(t.rejected_mwh, t.excess_mwh), np.maximum(t.reported_mwh - t.pmax_mwh, 0.0))
        demand = np.where(t.demand_mwh > 0, t.demand_mwh, np.maximum(t.total_verified_mw, FALLBACK_MIN_DEMAND_MWH))
        gap = (t.verified_mwh - t.demand_mwh) / np.maximum(t.demand_mwh, 1e-6)
        share = t.city_verified_w / np.maximum(t.verified_w, 1e-9)[:, None]
        trust = 1.0 - t.city_violation_rate
        out = cls(t, unsafe, demand, gap, np.ascontiguousarray(share), np.ascontiguousarray(trust))
        for value in (unsafe, demand, gap, out.city_share, out.city_trust):
            value.setflags(write=False)
        return out


class StepOutcome(NamedTuple):
    """Everything one step produces. Fields are floats (scalar) or arrays (batch)."""

    reward: Any
    matched_mwh: Any
    unmet_mwh: Any
    liquidity: Any
    peak_liquidity: Any
    drawdown: Any
    token_price: Any
    peak_price: Any
    token_drawdown: Any
    slippage: Any
    jitter: Any
    unsafe_backed_mwh: Any
    violation_rate: Any
    artificial_liquidity_mwh: Any
    fairness_variance: Any
    city_rewards: Any  # list of floats (scalar) or a (C, N) array (batch)


def city_reward(reward_tokens: Any, ell: Any, share: Any, trust: Any) -> Any:
    """A city's reward tokens: α G_b · share · (1 - violation rate) + ℓ · share · 0.01."""
    return reward_tokens * share * trust + ell * share * LIQUIDITY_SHARE_WEIGHT


def market_step(
    ops: Any,
    weights: RewardWeights,
    verified_mwh: Any,
    unsafe_supply_mwh: Any,
    demand_mwh: Any,
    city_share: Any,
    city_trust: Any,
    liquidity: Any,
    peak_liquidity: Any,
    token_price: Any,
    peak_price: Any,
    action: tuple,
    jitter: Any,
    noise: Any,
) -> StepOutcome:
    """Advance the market by one hour.

    Parameters
    ----------
    ops : ScalarOps or BatchOps
        Arithmetic back-end.
    verified_mwh, unsafe_supply_mwh, demand_mwh : float or ndarray
        G_v, X and the clearing demand Q_c of the hour, MWh.
    city_share, city_trust : tuple of floats (scalar) or (C, N) arrays (batch)
        Each city's share of verified power and 1 - its violation rate, cities alphabetical.
    liquidity, peak_liquidity : float or ndarray
        Pool L before the step and its running peak, MWh.
    token_price, peak_price : float or ndarray
        Token price p before the step and its running peak.
    action : (α, ℓ, b) tuple of float32-valued floats/arrays
        The executed action.
    jitter : float or ndarray
        J = |a - a_prev|_1 computed in float32 (see :mod:`.actions`).
    noise : float or ndarray
        The price shock, a normal(0, 0.004) draw.
    """
    alpha, ell, burn = action
    cap = weights.max_total_allocation
    # Physics gate: the share of invalid supply the action economically backs.
    backing = ops.minimum(alpha + ell, cap) / max(cap, 1e-9)
    unsafe_backed = unsafe_supply_mwh * backing
    backed = verified_mwh + unsafe_backed
    violation_rate = unsafe_backed / ops.maximum(backed, 1e-9)
    # Market clearing.
    liquidity_added = backed * ell
    reward_tokens = backed * alpha
    effective_demand = demand_mwh * ops.maximum(MIN_DEMAND_FACTOR, 1.0 - BURN_DEMAND_ELASTICITY * burn)
    available = liquidity + liquidity_added
    matched = ops.minimum(available, effective_demand)
    unmet = ops.maximum(effective_demand - available, 0.0)
    liquidity = ops.maximum(available - matched, 0.0)
    peak_liquidity = ops.maximum(peak_liquidity, liquidity)
    drawdown = 1.0 - liquidity / ops.maximum(peak_liquidity, 1e-12)
    slippage = effective_demand / ops.maximum(available + SLIPPAGE_DEPTH_OFFSET_MWH, SLIPPAGE_DEPTH_OFFSET_MWH)
    # Token price. Its gap is against the effective demand Q̃, unlike the observation's
    # ``supply_gap`` (raw trade demand), hence its own name.
    effective_supply_gap = (verified_mwh - effective_demand) / ops.maximum(effective_demand, 1e-6)
    price_return = (
        PRICE_GAP_WEIGHT * effective_supply_gap
        + PRICE_VOLUME_WEIGHT * matched
        + PRICE_BURN_WEIGHT * burn
        - PRICE_SLIPPAGE_WEIGHT * slippage
        - PRICE_ISSUANCE_WEIGHT * reward_tokens
        + noise
    )
    price_return = ops.clip(price_return, -MAX_PRICE_RETURN, MAX_PRICE_RETURN)
    token_price = ops.maximum(MIN_TOKEN_PRICE, token_price * (1.0 + price_return))
    peak_price = ops.maximum(peak_price, token_price)
    token_drawdown = 1.0 - token_price / ops.maximum(peak_price, 1e-12)
    # Spatial allocation of reward tokens.
    city_rewards = ops.per_city(city_reward, (reward_tokens, ell), (city_share, city_trust))
    fairness_variance = ops.city_variance(city_rewards)
    reward = (
        matched
        - weights.drawdown * drawdown
        - weights.jitter * jitter
        - weights.unmet * unmet
        - weights.fairness * fairness_variance
    )
    if weights.physics_penalty:
        reward = reward - weights.physics * (violation_rate + unsafe_backed)
    return StepOutcome(
        reward,
        matched,
        unmet,
        liquidity,
        peak_liquidity,
        drawdown,
        token_price,
        peak_price,
        token_drawdown,
        slippage,
        jitter,
        unsafe_backed,
        violation_rate,
        unsafe_backed * ell,
        fairness_variance,
        city_rewards,
    )
