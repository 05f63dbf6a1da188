"""The solar market as the Planner/Auditor layer sees it: its :class:`~solarchain_eval.tasks.governance_view.GovernanceView`.

The levers are (α, ℓ, b) with the market's :class:`~solarchain_eval.market.actions.ActionCodec`;
the risk signals are the observation's raw physics-violation rate ν, supply gap and static
slippage σ; the episode context is read from the environment's hourly table (the hours the
episode will run through, known before it starts); the counterfactual oracle is
:meth:`~solarchain_eval.envs.env.SolarChainEnv.counterfactual_step`, whose cost is V + A (the env's
``info["cost"]``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import MarketConfig
from ..market.actions import ActionCodec, DiscreteActions, initial_action
from ..market.dynamics import StepOutcome
from ..market.observation import OBS_GAP, OBS_SLIPPAGE, OBS_VIOLATION, OBSERVATION_NAMES
from ..records_schema import DIAGNOSTIC_OUTCOMES, Column
from ..tasks.governance_view import Action, EpisodeRisk, GovernancePrompts
from . import governance_prompts as text

LEVER_NAMES = ("reward_ratio", "liquidity_ratio", "burn_rate")
#: The previous step's outcome shown to the auditor (``info`` keys).
RECENT_FIELDS = (
    "reward",
    "matched_energy_MWh",
    "unmet_demand_MWh",
    "liquidity",
    "token_price",
    "slippage",
    "physics_violation_rate",
    "artificial_liquidity_MWh",
)
SOLAR_PROMPTS = GovernancePrompts(
    system=text.SYSTEM,
    planner_instruction=text.PLANNER_INSTRUCTION,
    auditor_instruction=text.AUDITOR_INSTRUCTION,
    agent_system=text.AGENT_SYSTEM,
    agent_instruction=text.AGENT_INSTRUCTION,
    agent_observation_units=text.AGENT_OBSERVATION_UNITS,
    agent_outcome_units=text.AGENT_OUTCOME_UNITS,
    lever_descriptions=text.AGENT_FIELD_DESCRIPTIONS,
)
#: :class:`StepOutcome` attribute of each diagnostics outcome column suffix (None: cost = V + A).
_ATTRIBUTES = {
    "violation_rate": "violation_rate",
    "unsafe_backed_MWh": "unsafe_backed_mwh",
    "cost": None,
    "reward": "reward",
    "matched_energy_MWh": "matched_mwh",
    "slippage": "slippage",
    "artificial_liquidity_MWh": "artificial_liquidity_mwh",
    "token_price": "token_price",  # the only field the step's price shock moves
}
#: Outcome fields in the schema's order: column suffix -> attribute (a suffix the schema adds
#: without an attribute here fails at import).
OUTCOME_FIELDS = {c.name: _ATTRIBUTES[c.name] for c in DIAGNOSTIC_OUTCOMES}


def _market(config: Any) -> MarketConfig:
    """The market section of a benchmark config, a market config itself, or the default (None)."""
    if config is None:
        return MarketConfig()
    return config if isinstance(config, MarketConfig) else config.market


@dataclass(frozen=True, eq=False)
class SolarGovernanceView:
    """The solar market's governance view (see the module docstring); build with :meth:`from_config`."""

    codec: ActionCodec
    market: MarketConfig
    lever_names: tuple[str, str, str] = LEVER_NAMES
    observation_names: tuple[str, ...] = OBSERVATION_NAMES
    recent_fields: tuple[str, ...] = RECENT_FIELDS
    prompts: GovernancePrompts = SOLAR_PROMPTS
    #: The diagnostics' outcome columns (the benchmark's schema) and the one the leaderboard's
    #: Δartificial liquidity reads (tasks/governance_view.py: diagnostic_outcomes_of, harm_outcome_of).
    diagnostic_outcomes: tuple[Column, ...] = DIAGNOSTIC_OUTCOMES
    harm_outcome: str = "artificial_liquidity_MWh"

    @classmethod
    def from_config(cls, config: Any = None) -> SolarGovernanceView:
        """The view of a :class:`~solarchain_eval.config.BenchmarkConfig` or its market section."""
        market = _market(config)
        return cls(ActionCodec.from_config(market), market)

    def risk_signals(self, observation: np.ndarray) -> tuple[float, float, float]:
        return float(observation[OBS_VIOLATION]), float(observation[OBS_GAP]), float(observation[OBS_SLIPPAGE])

    def initial_action(self, env: Any) -> Action:
        return initial_action(env.config.market)

    def proposal_decoder(self, env: Any, action_mode: str) -> Callable[[Any], Action]:
        # The env's own codec and discrete table: a governed discrete policy's index decodes as
        # the env would decode it.
        if action_mode == "discrete":
            return DiscreteActions.from_codec(env.codec, env.config.discrete_levels).decode
        if action_mode != "continuous":
            raise ValueError(f"unknown action mode {action_mode!r}")
        return env.codec.decode

    def episode_risk(self, env: Any, start_hour: int) -> EpisodeRisk:
        """ν, gap and σ of the episode's hours of the hourly table, and the prompt's statistics.

        ``supply_gap`` is the observation's (G_v - Q) / max(Q, 1e-6), unclipped, float64;
        energies in MWh.
        """
        table, steps = env.table, env.episode_steps
        hours = np.minimum(np.arange(start_hour, start_hour + steps), table.hours - 1)
        violation = np.ascontiguousarray(table.raw_violation_rate[hours])
        gap = np.ascontiguousarray(env.market_hours.supply_gap[hours])
        slippage = np.ascontiguousarray(table.static_slippage[hours])
        verified = np.ascontiguousarray(table.verified_mwh[hours])
        demand = np.ascontiguousarray(table.demand_mwh[hours])
        stats = {
            "max_violation_rate": float(np.max(violation)),
            "mean_violation_rate": float(np.mean(violation)),
            "min_supply_gap": float(np.min(gap)),
            "mean_supply_gap": float(np.mean(gap)),
            "mean_static_slippage": float(np.mean(slippage)),
            "max_static_slippage": float(np.max(slippage)),
            "mean_verified_supply_MWh": float(np.mean(verified)),
            "max_verified_supply_MWh": float(np.max(verified)),
            "mean_demand_MWh": float(np.mean(demand)),
            "hours_with_supply_shortfall": float(np.sum(gap < 0)),
        }
        return EpisodeRisk(
            start_hour=int(start_hour),
            episode_steps=int(steps),
            penalty_in_reward=not env.config.no_physics_penalty,
            signals=(violation, gap, slippage),
            statistics=stats,
        )

    def hour_of_day(self, env: Any, step: int) -> int:
        return (env.episode_start_hour + step) % 24

    def step_hours(self, env: Any, step: int, info: Mapping[str, Any]) -> tuple[int, int]:
        return int(info["absolute_hour"]), int(info["hour"])

    def executed_action(self, info: Mapping[str, Any], sent: np.ndarray) -> Action:
        # The env reports the executed levers (float32 values) in its info.
        return (info["reward_ratio"], info["liquidity_ratio"], info["burn_rate"])

    def oracle(self, env: Any) -> Callable[[Action], StepOutcome]:
        return env.counterfactual_step

    def outcome_cost(self, outcome: StepOutcome) -> float:
        """cost = V + A (the env's ``info["cost"]``, same order of operations)."""
        return outcome.violation_rate + outcome.unsafe_backed_mwh

    def outcome_reward(self, outcome: StepOutcome) -> float:
        return outcome.reward

    def outcome_values(self, outcome: StepOutcome) -> dict[str, float]:
        return {
            name: float(self.outcome_cost(outcome) if attribute is None else getattr(outcome, attribute))
            for name, attribute in OUTCOME_FIELDS.items()
        }
