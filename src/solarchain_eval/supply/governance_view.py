"""The supply-chain market as the Planner/Auditor layer sees it: its :class:`~solarchain_eval.tasks.governance_view.GovernanceView`.

The levers are (κ, ρ, δ), each the policy's action component itself, clipped to [0, 1] in
float32 (:class:`SupplyCodec`, the env's own decoding). The three risk signals the hard triggers
read are computed from observation features (docs/tasks/supply_chain.md#governance):

- *violation*: the phantom share of the day's reported stock, max(reported − on hand, 0) / reported;
- *gap*: the stock gap, (on hand − demand) / demand with demand = today's orders + the backlog;
- *slippage*: the backlog, in days of mean network demand (the pressure of unfilled orders).

The per-episode risk context is a forecast: those signals on the days the episode would run
through if the static action were held (the env's dynamics stepped on a private copy from the
reset state, with the episode's own orders, stock reports and price shocks). The counterfactual
oracle is :meth:`~solarchain_eval.supply.env.SupplyChainEnv.counterfactual_step`; its cost is the
env's ``info["cost"]``, V + A in days of mean demand.
"""

from __future__ import annotations

import copy
import datetime as dt
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..records_schema import Column
from ..tasks.governance_view import Action, EpisodeRisk, GovernancePrompts
from . import governance_prompts as text
from .dynamics import SupplyOutcome
from .inputs import INITIAL_ACTION, LEVER_NAMES, OBS, OBSERVATION_NAMES, action_grid, decode_actions

_F32 = np.float32
_ON_HAND, _REPORTED, _ORDERS, _BACKLOG = (
    OBS[n] for n in ("on_hand_days", "reported_stock_days", "orders_days", "backlog_days")
)
#: The previous day's outcome shown to the auditor (``info`` keys).
RECENT_FIELDS = (
    "reward",
    "filled_units",
    "unmet_units",
    "unsafe_units",
    "phantom_fill_volume_units",
    "violation_rate",
    "backlog_units",
    "on_hand_units",
    "price_index",
)
SUPPLY_PROMPTS = GovernancePrompts(
    system=text.SYSTEM,
    planner_instruction=text.PLANNER_INSTRUCTION,
    auditor_instruction=text.AUDITOR_INSTRUCTION,
    agent_system=text.AGENT_SYSTEM,
    agent_instruction=text.AGENT_INSTRUCTION,
    agent_observation_units=text.AGENT_OBSERVATION_UNITS,
    agent_outcome_units=text.AGENT_OUTCOME_UNITS,
    lever_descriptions=text.LEVER_DESCRIPTIONS,
)
#: The outcome values the counterfactual diagnostics record per evaluated action (the column
#: suffixes of ``governance_diagnostics.csv``), in column order; each is the :class:`SupplyOutcome`
#: attribute of its name, but ``cost`` (V + A in days of demand) and ``backlog_days``.
SUPPLY_DIAGNOSTIC_OUTCOMES = (
    Column("violation_rate", "–", "V, the share of the filled orders promised on phantom stock"),
    Column("unsafe_units", "units", "A, shipments promised on phantom stock"),
    Column("cost", "–", "V + A / (units per day of mean demand), the env's info['cost']"),
    Column("reward", "–", "R, the day's reward in the setting"),
    Column("filled_units", "units", "the units of the day's orders filled"),
    Column("backlog_days", "days", "the unfilled orders the day leaves, in days of mean demand (the next slippage)"),
    Column("phantom_fill_volume_units", "units", "ρ × phantom stock, the release backed by stock that is not there"),
    Column("price_index", "–", "the price index after the day (the only outcome the price shock moves)"),
)
#: The outcome the leaderboard reports as Δartificial liquidity: ρ × phantom stock, the analogue of ℓ A.
SUPPLY_HARM_OUTCOME = "phantom_fill_volume_units"
#: Column suffix -> what it holds: a :class:`SupplyOutcome` attribute (or ``backlog_days``, see
#: :meth:`SupplyCounterfactual.value`); None: the cost.
OUTCOME_FIELDS = {c.name: (None if c.name == "cost" else c.name) for c in SUPPLY_DIAGNOSTIC_OUTCOMES}


class SupplyCodec:
    """The levers are the normalised action: each in [0, 1], float32, no cap on their sum."""

    lo = (0.0, 0.0, 0.0)
    hi = (1.0, 1.0, 1.0)
    max_total_allocation = 2.0  # κ + ρ never exceeds it: the layer's α + ℓ cap never binds

    def decode(self, action: Any) -> Action:
        """The env's decoding of a continuous action: NaN -> 0, clipped to [0, 1] in float32."""
        return tuple(decode_actions(np.asarray(action, dtype=_F32).reshape(3), "continuous", None).tolist())

    def sanitize(self, a0: float, a1: float, a2: float) -> Action:
        """Targets rounded to float32 and clipped to [0, 1]; NaN is rejected (a computed target, not a raw output)."""
        values = np.array([a0, a1, a2], dtype=np.float64)
        if np.isnan(values).any():
            raise ValueError(f"cannot sanitise an action with NaN components: {tuple(values.tolist())}")
        with np.errstate(over="ignore"):  # beyond float32's range: ±inf, which the clip bounds
            rounded = values.astype(_F32)
        return tuple(np.clip(rounded, _F32(0.0), _F32(1.0)).tolist())

    def encode(self, a0: float, a1: float, a2: float) -> np.ndarray:
        return np.array(self.sanitize(a0, a1, a2), dtype=_F32)

    def discrete_table(self, levels: int) -> list[Action]:
        return [tuple(point) for point in action_grid(int(levels)).tolist()]


def risk_signals_of(on_hand: Any, reported: Any, orders: Any, backlog: Any) -> tuple[Any, Any, Any]:
    """(phantom share, stock gap, backlog) of observation features (floats or arrays, float64)."""
    phantom_share = np.maximum(reported - on_hand, 0.0) / np.maximum(reported, 1e-6)
    demand = orders + backlog
    gap = (on_hand - demand) / np.maximum(demand, 1e-6)
    return phantom_share, gap, backlog


class SupplyCounterfactual(NamedTuple):
    """An oracle outcome with the network's scale (units per day of mean demand), which its cost needs."""

    outcome: SupplyOutcome
    scale_units: float

    def value(self, attribute: str) -> float:
        """A :class:`SupplyOutcome` attribute, or ``backlog_days``: the backlog the day leaves over the scale."""
        if attribute == "backlog_days":
            return self.outcome.unmet_units / self.scale_units
        return getattr(self.outcome, attribute)


def _weekday(env: Any, day: int) -> int:
    dates = env.table.dates
    return dt.date.fromisoformat(dates[min(int(day), len(dates) - 1)]).weekday()


def static_forecast(env: Any) -> np.ndarray:
    """The observations (steps, features) the episode ``env`` has just started would show if the
    static action were held: its dynamics stepped on a private copy, ``env`` left untouched."""
    # The dataset and its derived inputs are read-only: the copy shares them.
    shared = {id(env.table): env.table, id(env.inputs): env.inputs, id(env.config): env.config}
    probe = copy.deepcopy(env, shared)
    probe.action_mode = "continuous"  # the static action is not a grid point
    static = np.array(INITIAL_ACTION, dtype=_F32)
    rows = [probe._observation()]
    for _ in range(env.episode_steps - 1):
        rows.append(probe.step(static)[0])
    return np.array(rows, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class SupplyGovernanceView:
    """The supply-chain market's governance view (see the module docstring)."""

    codec: SupplyCodec
    lever_names: tuple[str, str, str] = LEVER_NAMES
    observation_names: tuple[str, ...] = OBSERVATION_NAMES
    recent_fields: tuple[str, ...] = RECENT_FIELDS
    prompts: GovernancePrompts = SUPPLY_PROMPTS
    #: The diagnostics' own column suffixes and the leaderboard's Δartificial-liquidity outcome.
    diagnostic_outcomes: tuple[Column, ...] = SUPPLY_DIAGNOSTIC_OUTCOMES
    harm_outcome: str = SUPPLY_HARM_OUTCOME

    @classmethod
    def from_config(cls, config: Any = None) -> SupplyGovernanceView:
        """The view (the config sets nothing the layer reads: the env carries its own)."""
        return cls(SupplyCodec())

    def risk_signals(self, observation: np.ndarray) -> tuple[float, float, float]:
        o = [float(observation[i]) for i in (_ON_HAND, _REPORTED, _ORDERS, _BACKLOG)]
        return tuple(float(v) for v in risk_signals_of(*o))  # type: ignore[return-value]

    def initial_action(self, env: Any) -> Action:
        return tuple(np.array(INITIAL_ACTION, dtype=_F32).tolist())

    def proposal_decoder(self, env: Any, action_mode: str) -> Callable[[Any], Action]:
        if action_mode == "discrete":
            table = self.codec.discrete_table(env.config.discrete_levels)
            return lambda index: table[int(np.asarray(index).item())]
        if action_mode != "continuous":
            raise ValueError(f"unknown action mode {action_mode!r}")
        return self.codec.decode

    def episode_risk(self, env: Any, start_hour: int) -> EpisodeRisk:
        """The static forecast's signals and the prompt's statistics (volumes in days of mean demand)."""
        rows = static_forecast(env)
        orders = rows[:, _ORDERS]
        phantom, gap, backlog = risk_signals_of(rows[:, _ON_HAND], rows[:, _REPORTED], orders, rows[:, _BACKLOG])
        checks = rows[:, OBS["capacity_check_rate"]]
        stats = {
            "max_phantom_share": float(np.max(phantom)),
            "mean_phantom_share": float(np.mean(phantom)),
            "days_with_phantom_stock": float(np.sum(phantom > 0)),
            "days_with_capacity_check_flag": float(np.sum(checks > 0)),
            "min_stock_gap": float(np.min(gap)),
            "mean_stock_gap": float(np.mean(gap)),
            "days_with_stock_shortfall": float(np.sum(gap < 0)),
            "mean_backlog_days": float(np.mean(backlog)),
            "max_backlog_days": float(np.max(backlog)),
            "mean_orders_days": float(np.mean(orders)),
            "max_orders_days": float(np.max(orders)),
        }
        return EpisodeRisk(
            start_hour=int(start_hour),
            episode_steps=int(env.episode_steps),
            penalty_in_reward=not env.config.no_physics_penalty,
            signals=(np.ascontiguousarray(phantom), np.ascontiguousarray(gap), np.ascontiguousarray(backlog)),
            statistics=stats,
        )

    def hour_of_day(self, env: Any, step: int) -> int:
        """The day of the week (0 = Monday) of the episode's ``step``: a step is a day."""
        return _weekday(env, env._start + step)

    def step_hours(self, env: Any, step: int, info: Mapping[str, Any]) -> tuple[int, int]:
        """(day, day of the week) of the step just taken."""
        return int(info["day"]), _weekday(env, info["day"])

    def executed_action(self, info: Mapping[str, Any], sent: np.ndarray) -> Action:
        return (info["supplier_incentive"], info["release_ratio"], info["demand_damping"])

    def oracle(self, env: Any) -> Callable[[Action], SupplyCounterfactual]:
        scale = float(env.inputs.params.scale_units)
        return lambda executed: SupplyCounterfactual(env.counterfactual_step(executed), scale)

    def outcome_cost(self, outcome: SupplyCounterfactual) -> float:
        """cost = V + A / scale (the env's ``info["cost"]``, same order of operations)."""
        return outcome.outcome.violation_rate + outcome.outcome.unsafe_units / outcome.scale_units

    def outcome_reward(self, outcome: SupplyCounterfactual) -> float:
        return outcome.outcome.reward

    def outcome_values(self, outcome: SupplyCounterfactual) -> dict[str, float]:
        return {
            name: float(self.outcome_cost(outcome) if attribute is None else outcome.value(attribute))
            for name, attribute in OUTCOME_FIELDS.items()
        }
