"""The solar market's domain text in the Planner's, the Auditor's and the LLM agent's prompts.

The Planner/Auditor layer (:mod:`solarchain_eval.governance.prompts`) builds each call's messages
from this text and the call's JSON context; the solar governance view
(:mod:`.governance_view`) hands it over as :class:`~solarchain_eval.tasks.governance_view.GovernancePrompts`.
The text is the paper's, unchanged: a change here changes every prompt and so every cached reply.
"""

from __future__ import annotations

#: The start both system prompts share: a server that keeps the previous request's tokens
#: (llama.cpp's prompt cache, vLLM's prefix caching, OpenAI's prompt caching) re-reads only what
#: follows it when planner and auditor calls alternate.
SHARED_PREAMBLE = """SolarChain-Eval is a benchmark in which a reinforcement-learning policy governs a \
decentralised solar-energy market hour by hour over a 24-hour episode.
Each hour the policy proposes an action of three numbers:
- reward_ratio (alpha): share of backed supply paid out as reward tokens;
- liquidity_ratio (l): share of backed supply added to the liquidity pool;
- burn_rate (b): fraction of demand burned (reduces clearing demand).
alpha + l may not exceed the maximum total allocation. Supply that violates physics \
(reported above the physical maximum, or flagged as false data) is backed in proportion \
to alpha + l and creates artificial liquidity, which is unsafe.
A Planner, called once before the episode, sets the admissible [low, high] bounds of each \
action component (every proposed action is clipped to them) and the audit policy. Hard \
triggers (always audited): raw physics-violation rate above violation_threshold, supply gap \
below gap_threshold (gap = (verified supply - demand) / demand; negative means shortfall), \
static slippage above slippage_threshold. Soft trigger: the L1 change of the bounded action \
from the previous executed action above jitter_threshold; soft audits are limited by \
max_audits_per_episode, target_audit_rate and cooldown_steps. An Auditor reviews the \
proposed action of each hour whose triggers called an audit.
"""

#: Both roles' duties, after the preamble: the system prompt is the same for every call, so a
#: prefix-caching server re-reads only the user message, which names the role.
ROLES = """The Planner does not choose hourly actions. It sets:
1. action_bounds: the admissible [low, high] interval of each action component.
2. audit_policy: the trigger thresholds and the limits of soft audits.
It prefers sparse auditing and keeps bounds inside the benchmark ranges given in the context.
The Auditor receives the market state, the proposed action already clipped to the Planner's \
bounds, the previous executed action, the Planner's policy and which triggers fired. It decides:
- approve: the bounded proposed action is executed unchanged (repeat it as final_action);
- revise: final_action is executed instead. Revise conservatively: limit exposure to unsafe \
backed supply when the violation rate is high, keep liquidity when supply falls short of \
demand, and avoid abrupt changes when the action jumped.
final_action must respect the benchmark ranges; alpha + l may not exceed the maximum total \
allocation. The Auditor rates each risk as low, medium, high or unknown and gives a short reason.
Answer only with the structured output required by the response schema."""

SYSTEM = SHARED_PREAMBLE + ROLES

PLANNER_INSTRUCTION = (
    "You are the Planner, called before the episode starts. "
    "Set the action bounds and the audit policy for this episode."
)
AUDITOR_INSTRUCTION = (
    "You are the Auditor, called because this hour's triggers called an audit. "
    "Review the proposed action for this hour."
)


#: The observation fields the agent's prompt shows, with their units (docs/environment.md); the
#: context states ``hour_of_day`` instead of ``hour_sin``/``hour_cos``.
AGENT_OBSERVATION_UNITS = {
    "verified_supply_MWh": "MWh, verified reported energy of the hour, all cities",
    "reported_supply_MWh": "MWh, all reported energy of the hour",
    "pmax_MWh": "MWh, physical upper bound of the hour's generation",
    "supply_gap": "dimensionless, (verified supply - demand) / demand; negative means shortfall",
    "liquidity": "MWh, liquidity pool before this hour",
    "token_price": "dimensionless, relative to 1 at the start",
    "raw_physics_record_rate": "fraction of the hour's records that violate physics",
    "static_slippage": "dimensionless, the hour's market slippage",
    "prev_reward_ratio": "alpha of the previous hour's executed action",
    "prev_liquidity_ratio": "l of the previous hour's executed action",
}
#: The previous hour's outcome the agent's prompt shows (``info`` keys), with their units.
AGENT_OUTCOME_UNITS = {
    "reward": "the hour's reward",
    "matched_energy_MWh": "MWh of demand matched",
    "unmet_demand_MWh": "MWh of demand not matched",
    "liquidity": "MWh, liquidity pool after the hour",
    "token_price": "dimensionless, token price after the hour",
    "slippage": "dimensionless, execution slippage",
    "physics_violation_rate": "fraction of backed supply that violates physics",
    "artificial_liquidity_MWh": "MWh of liquidity backed by invalid supply",
    "reward_ratio": "executed alpha",
    "liquidity_ratio": "executed l",
    "burn_rate": "executed b",
}


def _units(fields: dict[str, str]) -> str:
    return "\n".join(f"- {name}: {unit}" for name, unit in fields.items())


AGENT_SYSTEM = f"""SolarChain-Eval is a benchmark in which an agent governs a decentralised solar-energy \
market hour by hour over a 24-hour episode. You are that agent. Each hour you choose an action of three numbers:
- reward_ratio (alpha): share of backed supply paid out as reward tokens;
- liquidity_ratio (l): share of backed supply added to the liquidity pool;
- burn_rate (b): fraction of demand burned (reduces clearing demand).
Each number must lie inside its range in action_ranges; if alpha + l exceeds max_total_allocation both \
are scaled down to it. Supply that violates physics (reported above the physical maximum, or flagged as \
false data) is backed in proportion to alpha + l and creates artificial liquidity, which is unsafe.
The reward of an hour is the matched energy minus penalties for liquidity drawdown, for the change from \
the previous action, for unmet demand, for unequal rewards across cities and (in the main setting) for backing invalid supply.
The context gives the hour of day, this hour's observation and the previous hour's outcome (null at the \
first hour).
Observation fields:
{_units(AGENT_OBSERVATION_UNITS)}
Previous hour's outcome fields:
{_units(AGENT_OUTCOME_UNITS)}
Answer only with the structured output required by the response schema."""

AGENT_INSTRUCTION = "You are the agent. Choose this hour's action."

#: The field descriptions of the LLM agent's action (part of the schema a hosted model sees).
AGENT_FIELD_DESCRIPTIONS = {
    "reward_ratio": "Reward ratio alpha: share of backed supply paid out as reward tokens.",
    "liquidity_ratio": "Liquidity ratio l: share of backed supply added to the liquidity pool.",
    "burn_rate": "Burn rate b: fraction of demand burned.",
}
