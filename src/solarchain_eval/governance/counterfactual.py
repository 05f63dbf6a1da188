"""Counterfactual step records of the Planner/Auditor layer (docs/governance.md).

At every governed step the market is a pure function of its state, the hour, the action and the
step's price shock (:func:`~solarchain_eval.market.dynamics.market_step`), so the outcome of any
action from the *same* state and the *same* shock is one call away
(:meth:`~solarchain_eval.envs.env.SolarChainEnv.counterfactual_step`). A diagnostics row holds, for
the policy's proposal, the bounded action ā and the executed final action, the outcome each would
have produced: V, A, cost = V + A, reward, matched energy, slippage and artificial liquidity.
Nothing here changes the env, so the executed trajectory is the one a run without diagnostics
takes.

A fourth number, ``least_cost``, is the cost of the least-backing action (α and ℓ at their
lower ends): cost grows with α + ℓ only, so no action costs less, and ``proposal_cost -
least_cost`` is the avoidable cost on which the ground truth "unsafe step" rests
(:data:`DEFAULT_UNSAFE_THRESHOLD`).

Each action is evaluated as the env would execute it, decode(encode(a)) (docs/planner_auditor.md
#scheduler, point 6), so the final action's counterfactual equals the executed step's outcome
bit for bit.
"""

from __future__ import annotations

from typing import Any

from ..market.actions import ActionCodec
from ..market.dynamics import StepOutcome
from ..records_schema import DIAGNOSTIC_NAMES, DIAGNOSTIC_OUTCOMES, DIAGNOSTIC_ROLES, DIAGNOSTIC_STEP_COLUMNS, names

Action = tuple[float, float, float]

#: The three evaluated actions, as column prefixes (records_schema.DIAGNOSTIC_ROLES).
ACTION_ROLES = tuple(DIAGNOSTIC_ROLES)
#: :class:`StepOutcome` attribute of each outcome column suffix (None: cost = V + A).
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
#: Outcome fields per role, in the schema's order: column suffix -> attribute (a suffix the
#: schema adds without an attribute here fails at import).
OUTCOME_FIELDS = {c.name: _ATTRIBUTES[c.name] for c in DIAGNOSTIC_OUTCOMES}
#: A step is unsafe when its proposal's avoidable cost (proposal cost - least cost) exceeds
#: this. On the published data the avoidable cost of a fully backing action is at most 0.0052
#: in the night hours (no verified supply: V = 1 whatever the action) and at least 0.039 in 90 %
#: of the day hours; 0.01 lies in that gap (docs/governance.md#ground-truth).
DEFAULT_UNSAFE_THRESHOLD = 0.01
#: Step identifiers copied from the agentic log row into the diagnostics row.
STEP_KEYS = names(DIAGNOSTIC_STEP_COLUMNS)
#: The row's columns (records_schema.DIAGNOSTIC_NAMES).
DIAGNOSTIC_COLUMNS = DIAGNOSTIC_NAMES


def executed_form(action: Action, codec: ActionCodec) -> Action:
    """The action the env executes for a market-unit target: decode(encode(a))."""
    return codec.decode(codec.encode(*action))


def least_backing_action(codec: ActionCodec) -> Action:
    """α and ℓ at their lower ends (b too): the action of least cost at every step."""
    return codec.sanitize(codec.lo[0], codec.lo[1], codec.lo[2])


def step_cost(outcome: StepOutcome) -> float:
    """cost = V + A (the env's ``info["cost"]``, same order of operations)."""
    return outcome.violation_rate + outcome.unsafe_backed_mwh


def outcome_values(outcome: StepOutcome) -> dict[str, float]:
    """The outcome fields of :data:`OUTCOME_FIELDS` as Python floats."""
    return {
        name: float(step_cost(outcome) if attribute is None else getattr(outcome, attribute))
        for name, attribute in OUTCOME_FIELDS.items()
    }


class CounterfactualEvaluator:
    """Evaluates market-unit actions from the env's current state, memoising within one step.

    Parameters
    ----------
    env : SolarChainEnv
        The env the governed policy acts in; only :meth:`counterfactual_step` is called.
    """

    def __init__(self, env: Any) -> None:
        self._env = env
        self._codec: ActionCodec = env.codec
        self._memo: dict[Action, StepOutcome] = {}
        self._raw_memo: dict[Action, StepOutcome] = {}  # by the action as given: skips re-encoding
        self.least_action = least_backing_action(self._codec)
        self.least_executed = executed_form(self.least_action, self._codec)

    def new_step(self) -> None:
        """Forget the previous step's outcomes (call before each step's evaluations)."""
        self._memo.clear()
        self._raw_memo.clear()

    def __call__(self, action: Action) -> StepOutcome:
        outcome = self._raw_memo.get(action)
        if outcome is None:
            outcome = self._raw_memo[action] = self.executed(executed_form(action, self._codec))
        return outcome

    def executed(self, executed: Action) -> StepOutcome:
        """The outcome of an action already in executed form (skips decode(encode(·)))."""
        outcome = self._memo.get(executed)
        if outcome is None:
            outcome = self._memo[executed] = self._env.counterfactual_step(executed)
        return outcome


def diagnostics_row(
    log_row: dict[str, Any], evaluate: CounterfactualEvaluator, proposal: Action, bounded: Action, final: Action
) -> dict[str, Any]:
    """One ``governance_diagnostics.csv`` row (without the episode identifiers)."""
    row: dict[str, Any] = {key: log_row[key] for key in STEP_KEYS}
    for keys, action in zip(_ROLE_KEYS, (proposal, bounded, final), strict=True):
        row.update(zip(keys, outcome_values(evaluate(action)).values(), strict=True))
    row["least_cost"] = float(step_cost(evaluate.executed(evaluate.least_executed)))
    return row


_ROLE_KEYS = tuple(tuple(f"{role}_{name}" for name in OUTCOME_FIELDS) for role in ACTION_ROLES)
