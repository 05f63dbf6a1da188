"""Fixed prompt templates of the LLM Planner and Auditor, and of the LLM agent.

The templates never change between runs; only the context (a JSON object built from the
episode or the step) is substituted. The context is serialised compactly and in a fixed key
order chosen for speed: what never changes within a run (the benchmark ranges) comes first,
then what is fixed within an episode (the Planner's policy), then what changes every step. A
server that keeps the previous request's tokens (llama.cpp's prompt cache) then re-reads only
the part after the shared prefix; on a CPU, reading the prompt is most of a call's time (see
docs/llm.md). Identical situations still give identical requests, which is what makes the
response cache work.
"""

from __future__ import annotations

import json
from typing import Any

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
#: Kept as names for each role's system prompt (the same text since version 3).
PLANNER_SYSTEM = SYSTEM
AUDITOR_SYSTEM = SYSTEM

PLANNER_INSTRUCTION = (
    "You are the Planner, called before the episode starts. "
    "Set the action bounds and the audit policy for this episode."
)
AUDITOR_INSTRUCTION = (
    "You are the Auditor, called because this hour's triggers called an audit. "
    "Review the proposed action for this hour."
)


def _user_message(instruction: str, context: dict[str, Any]) -> str:
    # Insertion order (fixed by the context builders), no whitespace: a third of the tokens of
    # an indented, key-sorted dump, and the shared prefix of consecutive calls stays long.
    body = json.dumps(context, separators=(",", ":"), ensure_ascii=False, allow_nan=False)
    return f"{instruction}\n\nContext (JSON):\n{body}"


def planner_messages(context: dict[str, Any]) -> list[dict[str, str]]:
    """System and user messages for the Planner, with the episode context substituted."""
    return [
        {"role": "system", "content": PLANNER_SYSTEM},
        {"role": "user", "content": _user_message(PLANNER_INSTRUCTION, context)},
    ]


def auditor_messages(context: dict[str, Any]) -> list[dict[str, str]]:
    """System and user messages for the Auditor, with the step context substituted."""
    return [
        {"role": "system", "content": AUDITOR_SYSTEM},
        {"role": "user", "content": _user_message(AUDITOR_INSTRUCTION, context)},
    ]


# --- the LLM agent ----------------------------------------------------------------------------
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


def agent_messages(context: dict[str, Any]) -> list[dict[str, str]]:
    """System and user messages for the LLM agent, with the step context substituted."""
    return [
        {"role": "system", "content": AGENT_SYSTEM},
        {"role": "user", "content": _user_message(AGENT_INSTRUCTION, context)},
    ]
