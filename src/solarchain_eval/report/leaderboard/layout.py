"""What a board ranks and shows, from its task's metric declarations (:class:`BoardLayout`).

The solar market's board is the paper's (:data:`COLUMNS`): ranked by cumulative reward, with the
five safety metrics beside it. Another task's board ranks its first utility metric whose
direction is ``higher`` and shows every other metric it declares.
"""

from __future__ import annotations

from dataclasses import dataclass

from ...tasks.base import MetricSpec, PaperReference, paper_reference_of
from ...tasks.registry import DEFAULT_TASK, get_task
from .sections import LeaderboardError

#: The ranked metric (of the solar market's board).
REWARD = "cumulative_reward"
#: Safety metrics shown beside the reward (their means; lower is better for each).
SAFETY_METRICS = (
    "physics_violation_rate",
    "artificial_liquidity_MWh",
    "mean_slippage",
    "action_jitter",
    "spatial_fairness_index",
)
#: The columns before, between and after the metrics' columns.
_KEYS = ("setting", "rank", "policy", "access", "source", "row_kind", "episodes", "start_days")
_IMPROVEMENT = ("best_baseline", "p_improvement", "p_improvement_low", "p_improvement_high")
_IDS = ("protocol_id", "board_protocol_id")


def ranked_columns(metric: str) -> tuple[str, ...]:
    """The ranked metric's columns: mean with its interval, sample std, IQM with its interval."""
    return tuple(f"{metric}_{part}" for part in ("mean", "low", "high", "std", "iqm", "iqm_low", "iqm_high"))


#: The columns of the solar market's ``leaderboard.csv``, in order.
COLUMNS = (*_KEYS, *ranked_columns(REWARD), *_IMPROVEMENT, *(f"{metric}_mean" for metric in SAFETY_METRICS), *_IDS)


@dataclass(frozen=True)
class BoardLayout:
    """What a board of one task ranks and shows, from the task's metric declarations.

    Attributes
    ----------
    task : str
    ranked : MetricSpec
        The metric policies are ranked by (higher is better): the task's first utility metric
        whose direction is ``higher`` (else its first metric whose direction is ``higher``).
    shown : tuple of MetricSpec
        The metrics whose means the board shows beside it: every other declared metric, or for a
        task with a paper reference its paper's board's metrics, then the declared metrics the
        paper does not cover.
    baselines : tuple of str
        The task's baselines, in its order (the best of them is the probability of improvement's Y).
    paper : PaperReference or None
        The task's paper reference (headers, the paper's protocol), if it has one.
    """

    task: str
    ranked: MetricSpec
    shown: tuple[MetricSpec, ...]
    baselines: tuple[str, ...]
    paper: PaperReference | None = None

    def columns(self) -> tuple[str, ...]:
        """The columns of ``leaderboard.csv``, in order (:data:`COLUMNS` for the solar market)."""
        shown = (f"{spec.name}_mean" for spec in self.shown)
        return (*_KEYS, *ranked_columns(self.ranked.name), *_IMPROVEMENT, *shown, *_IDS)

    def label(self, spec: MetricSpec) -> str | None:
        """The paper's board's short name of ``spec`` (None where it has none)."""
        return self.paper.headers.get(spec.name) if self.paper is not None else None


def board_layout(task: str = DEFAULT_TASK) -> BoardLayout:
    """The :class:`BoardLayout` of the task called ``task``.

    Raises
    ------
    LeaderboardError
        The task declares no metric whose direction is ``higher`` to rank by.
    """
    spec = get_task(task)
    rankable = [m for m in spec.metrics if m.dimension == "utility" and m.direction == "higher"]
    rankable += [m for m in spec.metrics if m.direction == "higher"]
    if not rankable:
        raise LeaderboardError(
            f"task {task!r} declares no metric whose direction is 'higher'; a board has none to rank by"
        )
    ranked = rankable[0]
    paper = paper_reference_of(spec)
    by_name = {m.name: m for m in spec.metrics}
    if paper is not None:
        shown = [by_name[n] for n in paper.board_metrics if n in by_name]
        shown += [m for m in spec.metrics if m.name not in paper.metrics and m is not ranked]
    else:
        shown = [m for m in spec.metrics if m is not ranked]
    return BoardLayout(task, ranked, tuple(shown), tuple(spec.baselines()), paper)
