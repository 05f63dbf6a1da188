"""Reference policies of the supply-chain market: static, random, myopic and the classic base-stock rule.

Each acts on the observation alone (docs/tasks/supply_chain.md#baseline-policies) in the
continuous action mode; Random is the solar market's (uniform actions, one generator per run).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..market.baselines import RandomPolicy
from .inputs import INITIAL_ACTION, OBS


@dataclass
class StaticPolicy:
    """(κ, ρ, δ) = (0.25, 0.75, 0.05) every day."""

    name: str = "static"
    action_mode: str = "continuous"
    stateless = True

    def __post_init__(self) -> None:
        self._action = np.array(INITIAL_ACTION, dtype=np.float32)
        self._action.setflags(write=False)

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> np.ndarray:
        return self._action


@dataclass
class MyopicPolicy:
    """One-day greedy rule on stock cover, backlog and the capacity check.

    κ = 0.35 if on-hand stock covers less than 4 days else 0.15; ρ = 0.95 if there is a backlog
    else 0.70; δ = 0.30 if the capacity check flags a report or the backlog exceeds a day's demand,
    else 0.05.
    """

    name: str = "myopic"
    action_mode: str = "continuous"
    stateless = True

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> np.ndarray:
        cover = float(observation[OBS["on_hand_days"]])
        backlog = float(observation[OBS["backlog_days"]])
        flagged = float(observation[OBS["capacity_check_rate"]])
        incentive = 0.35 if cover < 4.0 else 0.15
        release = 0.95 if backlog > 0.0 else 0.70
        damping = 0.30 if flagged > 0.0 or backlog > 1.0 else 0.05
        return np.array([incentive, release, damping], dtype=np.float32)


@dataclass
class BaseStockPolicy:
    """The periodic-review (s, S) rule (Scarf, 1960; base-stock when s = S) on the network's inventory position.

    Inventory position = reported stock + stock in transit - backlog - today's orders, in days of
    mean network demand, as a planner trusting the stock reports sees it. When it is below
    ``s = reorder_cover x (mean lead time + 1)`` days, production is ordered up to
    ``S = target_cover x (mean lead time + 1)`` days: κ = (S - position) / production capacity,
    clipped to [0, 1]. All reported stock is released (ρ = 1) and demand is not damped (δ = 0).
    """

    reorder_cover: float = 1.1
    target_cover: float = 1.1
    name: str = "base-stock"
    action_mode: str = "continuous"
    stateless = True

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> np.ndarray:
        o = observation
        position = (
            o[OBS["reported_stock_days"]] + o[OBS["in_transit_days"]] - o[OBS["backlog_days"]] - o[OBS["orders_days"]]
        )
        horizon = 7.0 * float(o[OBS["mean_lead_time_weeks"]]) + 1.0
        order = 0.0
        if position < self.reorder_cover * horizon:
            order = self.target_cover * horizon - float(position)
        incentive = min(max(order / max(float(o[OBS["production_capacity_days"]]), 1e-9), 0.0), 1.0)
        return np.array([incentive, 1.0, 0.0], dtype=np.float32)


SUPPLY_BASELINES = ("static", "random", "myopic", "base-stock")


def make_supply_baseline(name: str) -> StaticPolicy | RandomPolicy | MyopicPolicy | BaseStockPolicy:
    key = name.strip().lower()
    if key == "static":
        return StaticPolicy()
    if key == "random":
        return RandomPolicy()
    if key == "myopic":
        return MyopicPolicy()
    if key == "base-stock":
        return BaseStockPolicy()
    raise ValueError(f"unknown supply-chain baseline '{name}' (choose from {', '.join(SUPPLY_BASELINES)})")
