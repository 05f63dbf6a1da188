"""The report's tables: the paper's eleven data tables plus the statistics beyond the paper.

Each builder takes the loaded run and the options and returns a
:class:`~solarchain_eval.report.table_model.ReportTable`, or a
:class:`~solarchain_eval.report.table_model.Skipped` saying why the run cannot support it.
"""

from __future__ import annotations

from collections.abc import Callable

from ...governance.tables import governance_diagnostics
from ...loading import ReportData
from ...options import ReportOptions
from ...table_model import ReportTable, Skipped, to_csv, to_html, to_latex, to_markdown
from .actions import action_distributions
from .agentic import case_study, llm_operations, llm_triggers
from .deltas import agentic_effects, agentic_paired_deltas, physics_ablation_deltas
from .inference import overlap_warning, robust_summary, statistical_tests
from .performance import four_setting_aggregate, four_setting_learned, main_detail, main_performance

TableBuilder = Callable[[ReportData, ReportOptions], "ReportTable | Skipped"]

#: Every table, in the order the report shows them (the paper's body, its appendix, then ours).
TABLE_BUILDERS: tuple[TableBuilder, ...] = (
    main_performance,
    physics_ablation_deltas,
    agentic_effects,
    case_study,
    main_detail,
    four_setting_learned,
    four_setting_aggregate,
    llm_operations,
    llm_triggers,
    agentic_paired_deltas,
    action_distributions,
    statistical_tests,
    robust_summary,
    governance_diagnostics,
)


def build_tables(data: ReportData, options: ReportOptions) -> list[ReportTable | Skipped]:
    """Build every table the data supports; the rest come back as :class:`Skipped` with a reason."""
    return [builder(data, options) for builder in TABLE_BUILDERS]


__all__ = [
    "TABLE_BUILDERS",
    "ReportTable",
    "Skipped",
    "build_tables",
    "overlap_warning",
    "to_csv",
    "to_html",
    "to_latex",
    "to_markdown",
]
