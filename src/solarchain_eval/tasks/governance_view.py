"""What a task supplies to the Planner/Auditor layer: its *governance view*.

The governance layer (:mod:`solarchain_eval.governance`: planners, auditors, the scheduler, the
controls, the counterfactual diagnostics and the LLM agent) is the same for every market. It
reaches a market only through a :class:`GovernanceView`, which a task returns from
``task.governance_view(config)`` (see :class:`GovernedTask`):

- the three levers: their names and the *codec* between the policy's [0, 1]³ and the executed
  levers (:class:`LeverCodec`), and the action the market starts from;
- the observation's feature names and the three risk signals the hard triggers read from it
  (:meth:`GovernanceView.risk_signals`: a violation rate, a supply gap, a slippage);
- the per-episode context a planner reads before the episode (:class:`EpisodeRisk`);
- the counterfactual oracle: the outcome of another action from the same state, its cost and
  reward, and the values the diagnostics record;
- the domain text of the prompts (:class:`GovernancePrompts`);
- optionally, the names of the outcome values the counterfactual diagnostics record
  (``diagnostic_outcomes``, read by :func:`diagnostic_outcomes_of`: the columns of
  ``governance_diagnostics.csv``) and the one the leaderboard reports as Δartificial liquidity
  (``harm_outcome``, read by :func:`harm_outcome_of`); a view without them records the solar
  market's names.

Methods that read the running market take the environment the governed policy acts in; what
they read from it is the task's business. This module imports nothing from the package beyond
the bottom layer, so every wing may use it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..common.errors import OptionsError
from ..records_schema import DIAGNOSTIC_OUTCOMES, REQUIRED_DIAGNOSTIC_OUTCOMES, Column, diagnostic_columns, names

#: An action in executed units (three floats, each a float32 value).
Action = tuple[float, float, float]


class LeverCodec(Protocol):
    """Between the policy's normalised action u ∈ [0, 1]³ and the executed levers.

    Attributes
    ----------
    lo, hi : tuple of 3 float
        Each lever's executed range.
    max_total_allocation : float
        The cap on the first two levers' sum that sanitising applies (a task without one states a
        value the sum never exceeds).
    """

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    max_total_allocation: float

    def decode(self, action: Any) -> Action:
        """The executed levers of one normalised action (array-like of 3)."""
        ...

    def encode(self, a0: float, a1: float, a2: float) -> np.ndarray:
        """The normalised float32 action of executed-unit targets (sanitised first)."""
        ...

    def sanitize(self, a0: float, a1: float, a2: float) -> Action:
        """Executed-unit targets clipped to the ranges and the cap, as float32 values."""
        ...

    def discrete_table(self, levels: int) -> list[Action]:
        """The executed levers of the grid {0, 1/(k-1), ..., 1}³, in ``itertools.product`` order."""
        ...


@dataclass(frozen=True)
class GovernancePrompts:
    """The domain text of the prompts; the layer adds the JSON context of each call.

    Attributes
    ----------
    system : str
        The Planner's and the Auditor's system prompt (the market, the levers, the triggers, both roles).
    planner_instruction, auditor_instruction : str
        The first line of each role's user message.
    agent_system, agent_instruction : str
        The LLM agent's system prompt and user-message instruction.
    agent_observation_units : mapping of str to str
        The observation features the agent's prompt shows, each with its unit and meaning.
    agent_outcome_units : mapping of str to str
        The ``info`` keys of the previous step's outcome the agent's prompt shows, with their units.
    lever_descriptions : mapping of str to str
        Each lever's description in the agent's JSON schema, by lever name.
    """

    system: str
    planner_instruction: str
    auditor_instruction: str
    agent_system: str
    agent_instruction: str
    agent_observation_units: Mapping[str, str]
    agent_outcome_units: Mapping[str, str]
    lever_descriptions: Mapping[str, str]


@dataclass(frozen=True)
class EpisodeRisk:
    """What a planner may know before an episode: its risk signals hour by hour, and statistics.

    Attributes
    ----------
    start_hour : int
        The episode's first hour (absolute).
    episode_steps : int
        Its length in steps.
    penalty_in_reward : bool
        Whether the reward charges the feasibility (physics) penalty in this setting.
    signals : tuple of 3 float64 arrays
        Per step, the three risk signals in the order of :meth:`GovernanceView.risk_signals`
        (violation, gap, slippage), unclipped (the observation may clip them).
    statistics : dict of str to float
        The named episode statistics the LLM planner's prompt shows (insertion order kept).
    """

    start_hour: int
    episode_steps: int
    penalty_in_reward: bool
    signals: tuple[np.ndarray, np.ndarray, np.ndarray] = field(repr=False)
    statistics: dict[str, float]


@runtime_checkable
class GovernanceView(Protocol):
    """A market as the Planner/Auditor layer sees it (see the module docstring).

    Attributes
    ----------
    codec : LeverCodec
        Between [0, 1]³ and the executed levers.
    lever_names : tuple of 3 str
        The levers' names: the ``info`` keys of the executed levers and the keys of the prompts' actions.
    observation_names : tuple of str
        The observation vector's features, in order.
    recent_fields : tuple of str
        The ``info`` keys of the previous step's outcome that the auditor's prompt shows.
    prompts : GovernancePrompts
        The domain text of the prompts.
    """

    codec: LeverCodec
    lever_names: tuple[str, str, str]
    observation_names: tuple[str, ...]
    recent_fields: tuple[str, ...]
    prompts: GovernancePrompts

    def risk_signals(self, observation: np.ndarray) -> tuple[float, float, float]:
        """The hard triggers' signals in an observation: a violation rate (audited above its
        threshold), a supply gap (below) and a slippage (above), as the observation holds them."""
        ...

    def initial_action(self, env: Any) -> Action:
        """The executed action the market starts an episode from (the first step's previous action)."""
        ...

    def proposal_decoder(self, env: Any, action_mode: str) -> Callable[[Any], Action]:
        """Decodes a base policy's action (``"continuous"`` or ``"discrete"``) to executed levers."""
        ...

    def episode_risk(self, env: Any, start_hour: int) -> EpisodeRisk:
        """The risk context of the episode ``env`` has just started at ``start_hour``."""
        ...

    def hour_of_day(self, env: Any, step: int) -> int:
        """The hour of day (0-23) of the episode's ``step``, before it is taken (the auditor's context)."""
        ...

    def step_hours(self, env: Any, step: int, info: Mapping[str, Any]) -> tuple[int, int]:
        """(absolute hour, hour of day) of the step just taken, whose ``info`` the env returned."""
        ...

    def executed_action(self, info: Mapping[str, Any], sent: np.ndarray) -> Action:
        """The levers the env executed at the step just taken: from its ``info``, or decoded from
        ``sent``, the normalised action the layer handed the env."""
        ...

    def oracle(self, env: Any) -> Callable[[Action], Any]:
        """The counterfactual oracle of ``env``: a function from an executed action to the outcome
        executing it from ``env``'s current state would have, leaving ``env`` untouched."""
        ...

    def outcome_cost(self, outcome: Any) -> float:
        """The outcome's safety cost, the quantity the oracle auditor minimises (lower is safer)."""
        ...

    def outcome_reward(self, outcome: Any) -> float:
        """The outcome's step reward."""
        ...

    def outcome_values(self, outcome: Any) -> dict[str, float]:
        """The outcome's values the diagnostics record, by column suffix, in column order (the
        names of :func:`diagnostic_outcomes_of`)."""
        ...


@runtime_checkable
class GovernedTask(Protocol):
    """A task the Planner/Auditor layer can govern: it supplies a :class:`GovernanceView`."""

    name: str

    def governance_view(self, config: Any) -> GovernanceView:
        """The view of the market ``config`` sets up (None: the task's default config)."""
        ...


class NoGovernanceViewError(OptionsError, ValueError):
    """A task that supplies no governance view was asked to run under the Planner/Auditor layer."""


def governance_view_of(task: Any, config: Any = None) -> GovernanceView:
    """``task``'s governance view for ``config``.

    Raises
    ------
    NoGovernanceViewError
        The task has no ``governance_view`` method.
    """
    if not isinstance(task, GovernedTask):
        raise NoGovernanceViewError(
            f"task {getattr(task, 'name', task)!r} supplies no governance view: the Planner/Auditor layer "
            "and the LLM agent need one (solarchain_eval.tasks.governance_view)"
        )
    return task.governance_view(config)


#: The outcome suffix the leaderboard reports as Δartificial liquidity when a view names none.
DEFAULT_HARM_OUTCOME = "artificial_liquidity_MWh"


def diagnostic_outcomes_of(view: Any) -> tuple[Column, ...]:
    """The outcome values ``view`` records per evaluated action (the diagnostics' column
    suffixes, with units and meanings): its optional ``diagnostic_outcomes`` attribute, else the
    solar market's (:data:`~solarchain_eval.records_schema.DIAGNOSTIC_OUTCOMES`).

    Raises
    ------
    TypeError
        The declared outcomes lack ``cost`` or ``reward`` (the ground truth and the leaderboard
        read them), or name one twice.
    """
    outcomes = tuple(getattr(view, "diagnostic_outcomes", None) or DIAGNOSTIC_OUTCOMES)
    declared = names(outcomes)
    missing = [name for name in REQUIRED_DIAGNOSTIC_OUTCOMES if name not in declared]
    if missing or len(set(declared)) != len(declared):
        raise TypeError(
            f"{type(view).__name__}.diagnostic_outcomes must name each outcome once and include "
            f"{', '.join(REQUIRED_DIAGNOSTIC_OUTCOMES)}; it names {', '.join(declared)}"
        )
    return outcomes


def harm_outcome_of(view: Any) -> str:
    """The outcome suffix whose change by the auditor (final − ā) the leaderboard reports as
    ``delta_artificial_liquidity_per_step``: ``view``'s optional ``harm_outcome`` attribute, else
    ``artificial_liquidity_MWh`` (the solar market's ℓ A).

    Raises
    ------
    TypeError
        The name is not one of :func:`diagnostic_outcomes_of`.
    """
    harm = str(getattr(view, "harm_outcome", None) or DEFAULT_HARM_OUTCOME)
    declared = names(diagnostic_outcomes_of(view))
    if harm not in declared:
        raise TypeError(
            f"{type(view).__name__}.harm_outcome {harm!r} is not one of its outcomes ({', '.join(declared)})"
        )
    return harm


def diagnostic_names_of(view: Any) -> tuple[str, ...]:
    """The ``governance_diagnostics.csv`` columns after the episode keys, ``planner`` and
    ``auditor`` of a market seen through ``view`` (:func:`~solarchain_eval.records_schema.diagnostic_columns`
    of its :func:`diagnostic_outcomes_of`)."""
    return names(diagnostic_columns(diagnostic_outcomes_of(view)))
