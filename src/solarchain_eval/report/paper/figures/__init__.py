"""The report's figures (PNG and SVG), one builder per paper panel.

Each builder takes the loaded run, the options and the output folder and returns the
:class:`~solarchain_eval.report.figure_style.FigureFile` it wrote, or a
:class:`~solarchain_eval.report.table_model.Skipped` saying why the run cannot support it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ...figure_style import POLICY_COLOURS, FigureFile
from ...governance.figures import governance_figures
from ...loading import ReportData
from ...options import ReportOptions
from ...table_model import Skipped
from .ablation import liquidity_four_settings, liquidity_trajectories, paired_no_physics_delta
from .agentic import agentic_delta_scatter, audit_step_delta, case_action_revision, case_context, jitter_change
from .heatmap import city_hour_heatmaps
from .main import reward_distribution, reward_trajectory, trust_figures, utility_safety_frontier

FigureBuilder = Callable[[ReportData, ReportOptions, Path], "FigureFile | Skipped | list[FigureFile | Skipped]"]

#: Every figure builder, in the paper's order (main benchmark, ablation, agentic, case study, maps).
FIGURE_BUILDERS: tuple[FigureBuilder, ...] = (
    reward_distribution,
    utility_safety_frontier,
    reward_trajectory,
    trust_figures,
    paired_no_physics_delta,
    liquidity_four_settings,
    liquidity_trajectories,
    jitter_change,
    agentic_delta_scatter,
    audit_step_delta,
    case_action_revision,
    case_context,
    city_hour_heatmaps,
    governance_figures,
)


def build_figures(data: ReportData, options: ReportOptions, out_dir: Path) -> list[FigureFile | Skipped]:
    """Draw every figure the data supports into ``out_dir`` (PNG + SVG each)."""
    results: list[FigureFile | Skipped] = []
    for builder in FIGURE_BUILDERS:
        made = builder(data, options, out_dir)
        results.extend(made if isinstance(made, list) else [made])
    return results


__all__ = ["FIGURE_BUILDERS", "POLICY_COLOURS", "FigureFile", "Skipped", "build_figures"]
