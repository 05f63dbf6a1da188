"""The per-episode record schema: every ``metrics.csv`` column, with its unit and meaning, once.

The producers (:mod:`solarchain_eval.evaluation.metrics`, :mod:`solarchain_eval.governance.metrics`,
:mod:`solarchain_eval.evaluation.records`), the report (:mod:`solarchain_eval.report.loading`
and its tables) and the test fixtures take their column names from here, and
``tests/test_records_schema.py`` fails when one of them emits or reads a column this module
does not define. docs/metrics.md describes the same columns in prose.

This module imports nothing from the package, so any layer may import it.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Version of the record schema; bumped when a column is renamed or removed (docs/metrics.md#version-history).
RECORDS_SCHEMA_VERSION = 2


@dataclass(frozen=True)
class Column:
    """One per-episode column.

    Attributes
    ----------
    name : str
        The CSV column name.
    unit : str
        Its unit ("–" for dimensionless, "MWh", "tokens", "count", "text").
    meaning : str
        One line: what the value is.
    numeric : bool
        Whether the column holds numbers (the report checks and averages these).
    """

    name: str
    unit: str
    meaning: str
    numeric: bool = True


#: Rollout identifiers, first in every ``metrics.csv`` row.
EPISODE_KEY_COLUMNS = (
    Column("policy", "text", "policy name (static, random, myopic, ppo, ...)", numeric=False),
    Column("setting", "text", "evaluation setting (main, no_physics, llm, llm_no_physics)", numeric=False),
    Column("run_seed", "count", "the run seed"),
    Column("episode", "count", "episode index within the run seed, from 0"),
    Column("episode_seed", "count", "seed the episode's env was reset with"),
    Column("start_hour", "h", "the episode's first hour, counted from the dataset's first hour"),
)

#: Episode metrics of every setting (docs/metrics.md#episode-metrics), in column order.
EPISODE_METRIC_COLUMNS = (
    Column("cumulative_reward", "–", "sum of the step rewards R"),
    Column("episode_volume", "MWh", "sum of the matched energy M"),
    Column("physics_violation_rate", "–", "mean of the step violation rates V"),
    Column("max_drawdown", "–", "largest liquidity drawdown 1 - L_t / max_{s<=t} L_s over the episode"),
    Column("max_token_drawdown", "–", "largest token-price drawdown 1 - p_t / max_{s<=t} p_s over the episode"),
    Column("action_jitter", "–", "mean L1 distance between consecutive executed actions"),
    Column("mean_slippage", "–", "mean execution slippage"),
    Column("spatial_fairness_index", "tokens", "variance of the cities' reward totals over their mean |total|"),
    Column("artificial_liquidity_MWh", "MWh", "sum of the liquidity backed by invalid supply, ℓ A"),
    Column("final_liquidity", "MWh", "liquidity L after the last step"),
    Column("final_token_price", "–", "token price p after the last step"),
)

#: Columns added by runs behind the Planner/Auditor layer (docs/metrics.md#agentic-metrics).
AGENTIC_COLUMNS = (
    Column("plan_validity_rate", "–", "plans that passed validation / plans (1.0: an invalid plan fails the run)"),
    Column("audit_rate", "–", "audited steps / episode steps"),
    Column("revision_rate", "–", "revised audits / max(audits, 1)"),
    Column("modification_rate", "–", "steps whose executed action differs from the proposal / episode steps"),
    Column("mean_action_delta", "–", "sum of |final - proposed|_1 over the steps / episode steps"),
    Column("llm_retry_count", "count", "failed LLM attempts that a retry recovered (planner and auditor)"),
    Column("hard_trigger_rate", "–", "steps where a hard trigger held / episode steps"),
    Column("soft_trigger_rate", "–", "steps where the soft (jitter) trigger κ > τκ held / episode steps"),
    Column("not_triggered_rate", "–", "steps with neither trigger / episode steps"),
    Column("physics_trigger_rate", "–", "steps where ν > τν held / episode steps"),
    Column("gap_trigger_rate", "–", "steps where the supply gap < τΔ held / episode steps"),
    Column("slippage_trigger_rate", "–", "steps where σ > τσ held / episode steps"),
    Column("plan_violation_threshold", "–", "the plan's τν"),
    Column("plan_gap_threshold", "–", "the plan's τΔ"),
    Column("plan_jitter_threshold", "–", "the plan's τκ"),
    Column("plan_slippage_threshold", "–", "the plan's τσ"),
    Column("plan_audit_budget", "count", "the episode's audit budget B"),
    Column("governance_mode", "text", "the plan's label", numeric=False),
    Column("planner", "text", "planner kind", numeric=False),
    Column("auditor", "text", "auditor kind", numeric=False),
)

#: Columns added by the LLM agent (``llm-agent``, docs/llm.md#llm-as-the-agent): its model calls
#: in the episode. A cache hit counts as a call with its recorded latency and tokens, so a replay
#: writes the same values as the recording.
LLM_AGENT_COLUMNS = (
    Column("llm_agent_call_count", "count", "the LLM agent's model calls (one per step)"),
    Column("llm_agent_input_tokens", "LLM tokens", "prompt tokens of those calls, rejected replies included"),
    Column("llm_agent_output_tokens", "LLM tokens", "completion tokens of those calls, rejected replies included"),
    Column("llm_agent_latency_s", "s", "summed latency of the calls, every attempt included"),
    Column("llm_agent_max_latency_s", "s", "the slowest call's latency"),
    Column(
        "llm_agent_retry_count", "count", "failed attempts that a retry recovered (transport errors, rejected replies)"
    ),
    Column("llm_agent_invalid_reply_count", "count", "replies rejected by validation (out of range, malformed)"),
)

#: Columns renamed in a schema version: old name -> new name (readers map old files on load).
RENAMED_COLUMNS = {"llm_failure_count": "llm_retry_count"}
#: Columns removed in a schema version (readers drop them on load): name -> why.
REMOVED_COLUMNS = {"jitter_trigger_rate": "duplicated soft_trigger_rate"}


def names(columns: tuple[Column, ...]) -> tuple[str, ...]:
    """The names of ``columns``, in order."""
    return tuple(c.name for c in columns)


EPISODE_KEYS = names(EPISODE_KEY_COLUMNS)
METRIC_NAMES = names(EPISODE_METRIC_COLUMNS)
AGENTIC_METRIC_NAMES = names(AGENTIC_COLUMNS)
LLM_AGENT_METRIC_NAMES = names(LLM_AGENT_COLUMNS)
#: The numeric agentic columns (those a report averages).
AGENTIC_NUMERIC_NAMES = tuple(c.name for c in AGENTIC_COLUMNS if c.numeric)
#: The prefix of a user agent's own columns: what its ``end_episode`` returned, key ``k`` as
#: ``agent_k`` (checked: finite numbers and short text; see agents/validation.py). No other column
#: starts with it, so an agent can never write a metric, its name or an episode key.
AGENT_COLUMN_PREFIX = "agent_"


def record_columns(metric_columns: tuple[Column, ...] = EPISODE_METRIC_COLUMNS) -> dict[str, Column]:
    """Every column ``metrics.csv`` may hold, by name, in a run of a task whose episode metrics are
    ``metric_columns`` (a task's ``MetricSpec.column`` s; default: the solar market's), besides a
    user agent's ``agent_*`` columns."""
    return {c.name: c for c in (*EPISODE_KEY_COLUMNS, *metric_columns, *AGENTIC_COLUMNS, *LLM_AGENT_COLUMNS)}


#: Every column ``metrics.csv`` may hold, by name (a solar market run).
ALL_COLUMNS = record_columns()

#: Columns a sweep's tidy ``results.csv`` (docs/stress.md) adds to the ``metrics.csv`` columns of
#: each episode, besides one column per sweep axis.
SWEEP_RESULT_COLUMNS = (
    Column("point", "text", "the sweep point's id", numeric=False),
    Column("cost_limit", "–", "the point's PPO-Lagrangian limit D on the episode cost"),
    Column("episode_cost", "–", "Σ_t (V_t + A_t) over the episode, the cost PPO-Lagrangian constrains"),
)
SWEEP_RESULT_NAMES = names(SWEEP_RESULT_COLUMNS)
#: The episode's constraint cost Σ (V + A) (a ``results.csv`` column, from the per-step records).
EPISODE_COST = "episode_cost"

#: ``governance_diagnostics.csv`` (docs/governance.md#counterfactual-step-records), one row per
#: governed step: the episode keys, ``planner`` and ``auditor``, these step columns, then each
#: outcome of :data:`DIAGNOSTIC_OUTCOMES` for each action of :data:`DIAGNOSTIC_ROLES`, then ``least_cost``.
DIAGNOSTIC_STEP_COLUMNS = (
    Column("step", "count", "the step within the episode, from 0"),
    Column("audited", "–", "whether the auditor was called (True/False)", numeric=False),
    Column("decision", "text", "the auditor's verdict on ā (approve, revise); empty when not audited", numeric=False),
    Column("hard_trigger", "–", "whether a hard trigger held (True/False)", numeric=False),
    Column("soft_trigger", "–", "whether the soft (jitter) trigger held (True/False)", numeric=False),
)
#: The actions whose outcomes a diagnostics row holds (column prefixes).
DIAGNOSTIC_ROLES = {
    "proposal": "the policy's proposal",
    "bounded": "the bounded action ā",
    "final": "the executed final action",
}
#: The outcome of one action from the step's state and price shock (column suffixes).
DIAGNOSTIC_OUTCOMES = (
    Column("violation_rate", "–", "V, the physics-violation rate of the backed supply"),
    Column("unsafe_backed_MWh", "MWh", "A, the invalid supply the action backs"),
    Column("cost", "–", "V + A (the env's info['cost'])"),
    Column("reward", "–", "R, the step reward of the setting"),
    Column("matched_energy_MWh", "MWh", "M, the matched energy"),
    Column("slippage", "–", "the execution slippage"),
    Column("artificial_liquidity_MWh", "MWh", "ℓ A, the liquidity backed by invalid supply"),
    Column("token_price", "–", "p after the step (the only outcome the price shock moves)"),
)
#: The outcome suffixes every market's diagnostics hold: the oracle's cost (the ground truth's
#: "unsafe" rests on it) and the step reward (the leaderboard's Δreward).
REQUIRED_DIAGNOSTIC_OUTCOMES = ("cost", "reward")


def diagnostic_columns(outcomes: tuple[Column, ...] = DIAGNOSTIC_OUTCOMES) -> tuple[Column, ...]:
    """The ``governance_diagnostics.csv`` columns after the episode keys, ``planner`` and ``auditor``,
    for a market whose counterfactual outcomes are ``outcomes`` (the solar market's by default):
    the step columns, each outcome of each action of :data:`DIAGNOSTIC_ROLES`, then ``least_cost``."""
    return (
        *DIAGNOSTIC_STEP_COLUMNS,
        *(
            Column(f"{role}_{c.name}", c.unit, f"{c.meaning}, of {action}")
            for role, action in DIAGNOSTIC_ROLES.items()
            for c in outcomes
        ),
        Column("least_cost", "–", "the cost of the least-backing action (no action costs less at the step)"),
    )


#: The solar market's diagnostics columns (:func:`diagnostic_columns` of :data:`DIAGNOSTIC_OUTCOMES`).
DIAGNOSTIC_COLUMNS = diagnostic_columns(DIAGNOSTIC_OUTCOMES)
#: The ``governance_diagnostics.csv`` columns of the solar market after the episode keys, ``planner``
#: and ``auditor`` (another market's come from its governance view's ``diagnostic_outcomes``).
DIAGNOSTIC_NAMES = names(DIAGNOSTIC_COLUMNS)


def upgrade_columns(columns: list[str]) -> dict[str, str | None]:
    """How to read an older file: each renamed column -> its new name, each removed one -> None."""
    plan: dict[str, str | None] = {}
    for column in columns:
        if column in RENAMED_COLUMNS and RENAMED_COLUMNS[column] not in columns:
            plan[column] = RENAMED_COLUMNS[column]
        elif column in REMOVED_COLUMNS:
            plan[column] = None
    return plan
