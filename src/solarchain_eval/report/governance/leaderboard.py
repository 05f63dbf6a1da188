"""The governance leaderboard: planner/auditor combinations ranked by audit quality (docs/governance.md#leaderboard).

:func:`governance_leaderboard` turns the runs of
:func:`~solarchain_eval.experiments.governance.run_governance` into two ranked frames (pooled per
planner, auditor and setting with the LLM usage beside it; and per policy);
:func:`write_governance_leaderboard` writes them as CSV and Markdown with the two figures.
``solarchain-eval governance`` is these two calls and a printed table.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ...common.atomic_files import atomic_write_csv, atomic_write_text
from ...experiments.governance import CombinationRun, leaderboard_frames
from ...governance.counterfactual import DEFAULT_UNSAFE_THRESHOLD
from ...tasks.base import DEFAULT_STEPS_PER_DAY, steps_per_day_of
from ...tasks.governance_view import DEFAULT_HARM_OUTCOME, governance_view_of, harm_outcome_of
from ...tasks.registry import get_task
from ..statistics import DEFAULT_RESAMPLES
from ..table_model import to_markdown
from .audit_quality import audit_quality, step_frame
from .tables import quality_table, rank

#: File stems of the two tables.
LEADERBOARD = "leaderboard"
BY_POLICY = "leaderboard_by_policy"


@dataclass(frozen=True)
class GovernanceLeaderboard:
    """The ranked tables and the step diagnostics behind them.

    Attributes
    ----------
    ranked : pandas.DataFrame
        One row per planner, auditor and setting (policies pooled), ranked, with LLM calls,
        tokens, mean latency and wall time.
    by_policy : pandas.DataFrame
        The same per policy, ranked.
    diagnostics : pandas.DataFrame
        Every governed step's counterfactual diagnostics, with planner and auditor labels.
    threshold : float
        The avoidable cost above which a step counts as unsafe.
    resamples : int
        Bootstrap resamples behind the intervals.
    harm_outcome : str
        The diagnostics' outcome suffix behind ``delta_artificial_liquidity_per_step`` (the
        market's, :func:`~solarchain_eval.tasks.governance_view.harm_outcome_of`).
    steps_per_day : int
        The market's steps per day (:func:`~solarchain_eval.tasks.base.steps_per_day_of`): the
        intervals resample start days, ``start_hour // steps_per_day``.
    """

    ranked: pd.DataFrame
    by_policy: pd.DataFrame
    diagnostics: pd.DataFrame
    threshold: float
    resamples: int
    harm_outcome: str = DEFAULT_HARM_OUTCOME
    steps_per_day: int = DEFAULT_STEPS_PER_DAY


def governance_leaderboard(
    runs: Sequence[CombinationRun], *, threshold: float = DEFAULT_UNSAFE_THRESHOLD, resamples: int = DEFAULT_RESAMPLES
) -> GovernanceLeaderboard:
    """Rank the combinations of ``runs`` (all of one market) by audit quality (precision, recall,
    Δcost per step)."""
    tasks = sorted({run.task for run in runs})
    if len(tasks) > 1:
        raise ValueError(f"a governance leaderboard covers one task; the runs govern {', '.join(tasks)}")
    task = get_task(tasks[0]) if tasks else None
    harm = harm_outcome_of(governance_view_of(task)) if task is not None else DEFAULT_HARM_OUTCOME
    per_day = steps_per_day_of(task)
    diagnostics, usage = leaderboard_frames(runs)
    pooled = audit_quality(
        diagnostics,
        threshold=threshold,
        group_by=("planner", "auditor", "setting"),
        n_resamples=resamples,
        harm_outcome=harm,
        steps_per_day=per_day,
    )
    ranked = rank(pooled.merge(usage, on=["planner", "auditor", "setting"], how="left"))
    by_policy = rank(
        audit_quality(diagnostics, threshold=threshold, n_resamples=resamples, harm_outcome=harm, steps_per_day=per_day)
    )
    return GovernanceLeaderboard(ranked, by_policy, diagnostics, threshold, resamples, harm, per_day)


def write_governance_leaderboard(board: GovernanceLeaderboard, out_dir: Path) -> dict[str, Path]:
    """``leaderboard.{csv,md}``, ``leaderboard_by_policy.{csv,md}`` and ``figures/`` into ``out_dir``.

    Returns the written files by their path relative to ``out_dir``; each is written atomically.
    """
    from ..figure_style import FigureFile
    from .figures import precision_recall_figure, revision_scatter_figure

    out = Path(out_dir)
    files: dict[str, Path] = {}
    for key, frame, title, usage_columns in (
        (LEADERBOARD, board.ranked, "Governance leaderboard", True),
        (BY_POLICY, board.by_policy, "Governance leaderboard per policy", False),
    ):
        table = quality_table(
            frame,
            key=key,
            title=title,
            usage=usage_columns,
            threshold=board.threshold,
            harm_outcome=board.harm_outcome,
        )
        files[f"{key}.csv"] = atomic_write_csv(out / f"{key}.csv", frame)
        files[f"{key}.md"] = atomic_write_text(out / f"{key}.md", to_markdown(table))
    figures = out / "figures"
    pooled_by_pair = audit_quality(
        board.diagnostics,
        threshold=board.threshold,
        group_by=("planner", "auditor"),
        n_resamples=board.resamples,
        harm_outcome=board.harm_outcome,
        steps_per_day=board.steps_per_day,
    )
    steps = step_frame(board.diagnostics, board.threshold, board.harm_outcome, board.steps_per_day)
    made = [
        precision_recall_figure(pooled_by_pair, figures),
        revision_scatter_figure(steps, board.diagnostics, figures),
    ]
    for figure in made:
        if isinstance(figure, FigureFile):  # the revision scatter is skipped when nothing was revised
            files[f"figures/{figure.png.name}"] = figure.png
            files[f"figures/{figure.svg.name}"] = figure.svg
    return files
