"""The ``info`` of a solar market step: its keys (:data:`STEP_INFO_KEYS`) and values
(:func:`step_info`), one formula for the single env, the vector env and the JAX env.
"""

from __future__ import annotations

from typing import Any

from ..market.dynamics import StepOutcome

#: Per-step quantities in ``info`` (docs/environment.md#info, the original release's names), plus
#: ``fairness_variance`` (F) and ``cost`` = V + A. ``info`` also has ``step`` and ``city_rewards``.
STEP_INFO_KEYS = (
    "reward",
    "absolute_hour",
    "episode_start_hour",
    "hour",
    "reward_ratio",
    "liquidity_ratio",
    "burn_rate",
    "verified_supply_MWh",
    "reported_supply_MWh",
    "physics_excess_MWh",
    "unsafe_backed_MWh",
    "artificial_liquidity_MWh",
    "physics_violation_rate",
    "raw_physics_record_rate",
    "demand_MWh",
    "matched_energy_MWh",
    "unmet_demand_MWh",
    "liquidity",
    "liquidity_depth",
    "token_price",
    "drawdown",
    "token_drawdown",
    "action_jitter",
    "slippage",
    "fairness_variance",
    "cost",
)


def step_info(
    out: StepOutcome, executed: tuple, hour: Any, start: Any, hour_inputs: tuple, depth_scale: float
) -> dict[str, Any]:
    """The ``info`` entries of :data:`STEP_INFO_KEYS` for one step (floats or per-sub-env arrays).

    ``hour_inputs`` is (G_v, G_r, X, ν, Q_c) of the step's hour.
    """
    verified, reported, unsafe, raw_rate, demand = hour_inputs
    return {
        "reward": out.reward,
        "absolute_hour": hour,
        "episode_start_hour": start,
        "hour": hour % 24,
        "reward_ratio": executed[0],
        "liquidity_ratio": executed[1],
        "burn_rate": executed[2],
        "verified_supply_MWh": verified,
        "reported_supply_MWh": reported,
        "physics_excess_MWh": unsafe,
        "unsafe_backed_MWh": out.unsafe_backed_mwh,
        "artificial_liquidity_MWh": out.artificial_liquidity_mwh,
        "physics_violation_rate": out.violation_rate,
        "raw_physics_record_rate": raw_rate,
        "demand_MWh": demand,
        "matched_energy_MWh": out.matched_mwh,
        "unmet_demand_MWh": out.unmet_mwh,
        "liquidity": out.liquidity,
        "liquidity_depth": out.liquidity / depth_scale,
        "token_price": out.token_price,
        "drawdown": out.drawdown,
        "token_drawdown": out.token_drawdown,
        "action_jitter": out.jitter,
        "slippage": out.slippage,
        "fairness_variance": out.fairness_variance,
        "cost": out.violation_rate + out.unsafe_backed_mwh,
    }
