"""Governance diagnostics tables: audit quality per planner/auditor (docs/governance.md).

:func:`quality_table` renders any frame of :func:`~solarchain_eval.report.governance.audit_quality.audit_quality`
rows (the leaderboard of ``solarchain-eval governance`` and the report's section);
:func:`governance_diagnostics` is the report's table builder.
"""

from __future__ import annotations

import pandas as pd

from ...governance.counterfactual import DEFAULT_UNSAFE_THRESHOLD
from ...tasks.base import steps_per_day_of
from ...tasks.governance_view import DEFAULT_HARM_OUTCOME, GovernedTask, governance_view_of, harm_outcome_of
from ..loading import ReportData
from ..naming import AGENTIC_REWARD_LABELS, policy_label, setting_label
from ..options import ReportOptions
from ..table_model import Column, ReportTable, Row, Skipped, fixed, integer, text, with_interval
from .audit_quality import GROUP_KEYS, audit_quality

NO_DIAGNOSTICS = (
    "the run has no governance_diagnostics.csv: evaluate with --agentic planner_auditor --diagnostics "
    "(or run solarchain-eval governance)"
)


def _ci(name: str, digits: int):
    def render(row: Row) -> str:
        return with_interval(row[name], row[f"{name}_low"], row[f"{name}_high"], digits)

    return render


def _plain(name: str, digits: int):
    return lambda row: fixed(row[name], digits)


def rank(quality: pd.DataFrame) -> pd.DataFrame:
    """Leaderboard order: lowest Δcost per step first, then highest Δreward per step, then names."""
    names = [c for c in ("planner", "auditor", "policy", "setting") if c in quality.columns]
    ordered = quality.sort_values(
        ["delta_cost_per_step", "delta_reward_per_step", *names], ascending=[True, False, *[True] * len(names)]
    )
    return ordered.reset_index(drop=True).assign(rank=lambda f: range(1, len(f) + 1))


def harm_header(harm_outcome: str = DEFAULT_HARM_OUTCOME) -> str:
    """The header of the ``delta_artificial_liquidity_per_step`` column: ``Δ Art. Liq. / step`` for
    the solar market's outcome, else ``Δ <outcome> / step`` (the name the market's view declares)."""
    return "Δ Art. Liq. / step" if harm_outcome == DEFAULT_HARM_OUTCOME else f"Δ {harm_outcome} / step"


def quality_columns(frame: pd.DataFrame, usage: bool, harm_outcome: str = DEFAULT_HARM_OUTCOME) -> list[Column]:
    """Printed columns: identifiers present in ``frame``, rates and effects, LLM usage if asked
    (``harm_outcome``: the diagnostics' outcome behind the Δartificial-liquidity column, which heads it)."""
    columns = [Column("#", integer("rank"), align="r")] if "rank" in frame.columns else []
    labels = {"planner": "Planner", "auditor": "Auditor", "setting": "Reward", "policy": "Policy"}
    for key, header in labels.items():
        if key in frame.columns:
            render = text(key)
            if key == "policy":
                render = lambda row: policy_label(str(row["policy"]))  # noqa: E731
            if key == "setting":  # the reward of the agentic setting: the layer is named in its own columns
                render = lambda row: AGENTIC_REWARD_LABELS.get(str(row["setting"]), setting_label(str(row["setting"])))  # noqa: E731
            columns.append(Column(header, render, align="l"))
    columns += [
        Column("Audit rate", _plain("audit_rate", 3)),
        Column("Unsafe share", _plain("unsafe_share", 3)),
        Column("Precision", _ci("precision", 3)),
        Column("Recall", _ci("recall", 3)),
        Column("False alarms", _plain("false_alarm_rate", 3)),
        Column("Δ Cost / step", _ci("delta_cost_per_step", 4)),
        Column("Δ Reward / step", _ci("delta_reward_per_step", 4)),
        Column(harm_header(harm_outcome), _plain("delta_artificial_liquidity_per_step", 5)),
        Column("Δ Cost vs none / step", _plain("total_delta_cost_per_step", 4)),
        Column("Lowered cost", _plain("revisions_lowering_cost", 3)),
        Column("Harmful", _plain("revisions_harmful", 3)),
    ]
    if usage:
        columns += [
            Column("Calls", integer("llm_calls"), align="r"),
            Column("Tokens", integer("llm_tokens"), align="r"),
            Column("Latency (s)", _plain("llm_mean_latency_s", 3)),
        ]
    return columns


def quality_table(
    quality: pd.DataFrame,
    *,
    key: str,
    title: str,
    usage: bool = False,
    threshold: float = DEFAULT_UNSAFE_THRESHOLD,
    harm_outcome: str = DEFAULT_HARM_OUTCOME,
) -> ReportTable:
    """A :class:`ReportTable` of audit-quality rows (ranked when they carry ``rank``; ``harm_outcome``:
    see :func:`quality_columns`)."""
    steps, days = int(quality["steps"].sum()), int(quality["start_days"].max()) if len(quality) else 0
    return ReportTable(
        key=key,
        label=f"tab:{key}",
        title=title,
        caption=(
            f"{title}. Ground truth: a step is unsafe when its proposal's avoidable cost (proposal cost minus the "
            f"least cost any action reaches from the same state) exceeds {threshold:g}. Precision, recall and the "
            "false-alarm rate compare audited with unsafe steps. Δ columns are the executed final action minus the "
            "bounded action ā, evaluated from the same state and price shock, averaged over all governed steps ('vs none': "
            "final minus the proposal, i.e. bounds and audits against no governance at the same states); "
            "'Lowered cost' and 'Harmful' (cost not lowered, reward lost) are shares of revisions. Brackets are 95 % "
            "cluster-bootstrap intervals over start days."
        ),
        columns=quality_columns(quality, usage, harm_outcome),
        data=quality,
        basis=f"{steps} governed steps; up to {days} start days per row",
    )


def harm_outcome(data: ReportData) -> str:
    """The diagnostics' outcome suffix behind Δartificial liquidity for the report's task (its
    governance view's, :func:`~solarchain_eval.tasks.governance_view.harm_outcome_of`)."""
    return harm_outcome_of(governance_view_of(data.task_spec))


def has_governance_section(data: ReportData) -> bool:
    """Whether the report shows the governance section (table and figures, made or skipped): the
    run has counterfactual diagnostics, or its task has a governance view (then the section says
    how to record them)."""
    return not data.diagnostics.empty or isinstance(data.task_spec, GovernedTask)


def report_audit_quality(
    data: ReportData, options: ReportOptions, group_by: tuple[str, ...] = GROUP_KEYS
) -> pd.DataFrame:
    """:func:`~solarchain_eval.report.governance.audit_quality.audit_quality` of the run's
    diagnostics, read the way its task declares them: the harm outcome its governance view names
    and its steps per day (episodes are clustered by start day, ``start_hour // steps_per_day``)."""
    return audit_quality(
        data.diagnostics,
        group_by=group_by,
        n_resamples=options.n_resamples,
        seed=options.seed,
        harm_outcome=harm_outcome(data),
        steps_per_day=steps_per_day_of(data.task_spec),
    )


def governance_diagnostics(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """The report's "Governance diagnostics" table: audit quality per planner/auditor, policy, setting."""
    key, title = "governance_diagnostics", "Governance diagnostics: audit quality"
    if data.diagnostics.empty:
        return Skipped(key, title, NO_DIAGNOSTICS)
    return quality_table(
        rank(report_audit_quality(data, options)), key=key, title=title, harm_outcome=harm_outcome(data)
    )
