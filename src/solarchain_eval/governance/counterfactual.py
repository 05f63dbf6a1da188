"""Counterfactual step records of the Planner/Auditor layer (docs/governance.md).

At every governed step the market's governance view answers what any action would have produced
from the *same* state (for the solar market: the same hour and the same price shock, as the
market is a pure function of them; :meth:`~solarchain_eval.envs.env.SolarChainEnv.counterfactual_step`).
A diagnostics row holds, for the policy's proposal, the bounded action ā and the executed final
action, the outcome values the view records for each (the solar market: V, A, cost = V + A,
reward, matched energy, slippage, artificial liquidity and token price). Nothing here changes the
env, so the executed trajectory is the one a run without diagnostics takes.

A further number, ``least_cost``, is the cost of the least-backing action (every lever at its
lower end): for the solar market cost grows with α + ℓ only, so no action costs less, and
``proposal_cost - least_cost`` is the avoidable cost on which the ground truth "unsafe step"
rests (:data:`DEFAULT_UNSAFE_THRESHOLD`).

Each action is evaluated as the env would execute it, decode(encode(a)) (docs/planner_auditor.md
#scheduler, point 6), so the final action's counterfactual equals the executed step's outcome
bit for bit.
"""

from __future__ import annotations

from typing import Any

from ..records_schema import DIAGNOSTIC_NAMES, DIAGNOSTIC_OUTCOMES, DIAGNOSTIC_ROLES, DIAGNOSTIC_STEP_COLUMNS, names
from ..tasks.governance_view import GovernanceView, LeverCodec
from .view import default_view, resolve_view

Action = tuple[float, float, float]

#: The three evaluated actions, as column prefixes (records_schema.DIAGNOSTIC_ROLES).
ACTION_ROLES = tuple(DIAGNOSTIC_ROLES)
#: The outcome columns (suffixes) of the default task's diagnostics, in the schema's order.
OUTCOME_FIELDS = names(DIAGNOSTIC_OUTCOMES)
#: A step is unsafe when its proposal's avoidable cost (proposal cost - least cost) exceeds
#: this. On the published data the avoidable cost of a fully backing action is at most 0.0052
#: in the night hours (no verified supply: V = 1 whatever the action) and at least 0.039 in 90 %
#: of the day hours; 0.01 lies in that gap (docs/governance.md#ground-truth).
DEFAULT_UNSAFE_THRESHOLD = 0.01
#: Step identifiers copied from the agentic log row into the diagnostics row.
STEP_KEYS = names(DIAGNOSTIC_STEP_COLUMNS)
#: The solar market's row columns (records_schema.DIAGNOSTIC_NAMES; another market's come from its
#: governance view, tasks.governance_view.diagnostic_names_of).
DIAGNOSTIC_COLUMNS = DIAGNOSTIC_NAMES


def executed_form(action: Action, codec: LeverCodec) -> Action:
    """The action the env executes for a market-unit target: decode(encode(a))."""
    return codec.decode(codec.encode(*action))


def least_backing_action(codec: LeverCodec) -> Action:
    """Every lever at its lower end: for the solar market (α, ℓ low) the action of least cost at every step."""
    return codec.sanitize(codec.lo[0], codec.lo[1], codec.lo[2])


def step_cost(outcome: Any, view: GovernanceView | None = None) -> float:
    """The outcome's cost by the market's view (the solar market: V + A, the env's ``info["cost"]``)."""
    return (view if view is not None else default_view()).outcome_cost(outcome)


def outcome_values(outcome: Any, view: GovernanceView | None = None) -> dict[str, float]:
    """The outcome's diagnostics values by column suffix, as Python floats."""
    return (view if view is not None else default_view()).outcome_values(outcome)


class CounterfactualEvaluator:
    """Evaluates market-unit actions from the env's current state, memoising within one step.

    Parameters
    ----------
    env : gymnasium.Env
        The env the governed policy acts in; only the view's oracle reads it.
    view : GovernanceView, optional
        The market's governance view (None: the default task's view of ``env.config``).
    """

    def __init__(self, env: Any, view: GovernanceView | None = None) -> None:
        self._env = env
        self.view = view if view is not None else resolve_view(env.config)
        self._codec: LeverCodec = self.view.codec
        self._oracle = self.view.oracle(env)
        self._memo: dict[Action, Any] = {}
        self._raw_memo: dict[Action, Any] = {}  # by the action as given: skips re-encoding
        self.least_action = least_backing_action(self._codec)
        self.least_executed = executed_form(self.least_action, self._codec)

    def new_step(self) -> None:
        """Forget the previous step's outcomes (call before each step's evaluations)."""
        self._memo.clear()
        self._raw_memo.clear()

    def __call__(self, action: Action) -> Any:
        outcome = self._raw_memo.get(action)
        if outcome is None:
            outcome = self._raw_memo[action] = self.executed(executed_form(action, self._codec))
        return outcome

    def executed(self, executed: Action) -> Any:
        """The outcome of an action already in executed form (skips decode(encode(·)))."""
        outcome = self._memo.get(executed)
        if outcome is None:
            outcome = self._memo[executed] = self._oracle(executed)
        return outcome


def diagnostics_row(
    log_row: dict[str, Any], evaluate: CounterfactualEvaluator, proposal: Action, bounded: Action, final: Action
) -> dict[str, Any]:
    """One ``governance_diagnostics.csv`` row (without the episode identifiers)."""
    row: dict[str, Any] = {key: log_row[key] for key in STEP_KEYS}
    view = evaluate.view
    for role, action in zip(ACTION_ROLES, (proposal, bounded, final), strict=True):
        row.update({f"{role}_{name}": value for name, value in view.outcome_values(evaluate(action)).items()})
    row["least_cost"] = float(view.outcome_cost(evaluate.executed(evaluate.least_executed)))
    return row
