"""Governance diagnostics figures: precision vs recall per auditor, Δcost vs Δreward per revision."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ...tasks.base import steps_per_day_of
from ..figure_style import EXTRA_COLOURS, FigureFile, new_figure, save_figure
from ..loading import ReportData
from ..options import ReportOptions
from ..table_model import Skipped
from .audit_quality import step_frame
from .tables import NO_DIAGNOSTICS, harm_outcome, report_audit_quality


def _label(row: pd.Series | dict) -> str:
    return f"{row['planner']} / {row['auditor']}"


#: Auditor colours (colour-blind safe first, then more), planner markers: combinations stay apart.
AUDITOR_COLOURS = ("#0072b2", "#d55e00", "#009e73", "#cc79a7", "#e69f00", "#56b4e9", *EXTRA_COLOURS)
PLANNER_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def _colours(labels: list[str]) -> dict[str, str]:
    return {label: AUDITOR_COLOURS[i % len(AUDITOR_COLOURS)] for i, label in enumerate(sorted(set(labels)))}


def _style(quality: pd.DataFrame) -> dict[str, tuple[str, str]]:
    """(colour by auditor, marker by planner) of each "planner / auditor" label."""
    colours = _colours([str(a) for a in quality["auditor"]])
    planners = sorted({str(p) for p in quality["planner"]})
    return {
        _label(row): (colours[str(row["auditor"])], PLANNER_MARKERS[planners.index(str(row["planner"])) % 8])
        for _, row in quality.iterrows()
    }


def precision_recall_figure(
    quality: pd.DataFrame, out_dir: Path, key: str = "governance_precision_recall"
) -> FigureFile:
    """One point per (planner, auditor) row with its bootstrap intervals; the unsafe share is the
    precision a chance auditor reaches (dotted line)."""
    title = "Audit precision vs recall"
    labels = [_label(row) for _, row in quality.iterrows()]
    style = _style(quality)
    with new_figure(figsize=(6.4, 3.6)) as (figure, axes):
        ax = axes[0, 0]
        for label, (_, row) in zip(labels, quality.iterrows(), strict=True):
            x, y = row["recall"], row["precision"]
            xerr = [[max(x - row["recall_low"], 0)], [max(row["recall_high"] - x, 0)]]
            yerr = [[max(y - row["precision_low"], 0)], [max(row["precision_high"] - y, 0)]]
            colour, marker = style[label]
            ax.errorbar(
                x, y, xerr=xerr, yerr=yerr, fmt=marker, color=colour, label=label, capsize=2, alpha=0.8, markersize=6
            )
        ax.axhline(float(quality["unsafe_share"].mean()), color="#555555", linestyle=":", linewidth=1)
        ax.set_xlim(-0.02, 1.02)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("Recall (unsafe steps audited)")
        ax.set_ylabel("Precision (audited steps unsafe)")
        ax.set_title(title)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
        caption = (
            "Precision vs recall of each planner/auditor's audited steps against the counterfactual ground truth "
            "(95 % cluster-bootstrap intervals over start days); the dotted line is the unsafe share, the precision "
            "of auditing at random."
        )
        return save_figure(figure, out_dir, key, title, caption)


def revision_scatter_figure(
    steps: pd.DataFrame, diagnostics: pd.DataFrame, out_dir: Path, key: str = "governance_revision_deltas"
) -> FigureFile | Skipped:
    """Δcost (x) vs Δreward (y) of every revision, final - ā, coloured by planner/auditor."""
    title = "Revisions: Δ cost vs Δ reward"
    revised = steps["revised"] > 0
    if not revised.any():
        return Skipped(key, title, "no audited step was revised")
    labels = diagnostics.loc[revised].apply(_label, axis=1)
    style = _style(diagnostics.loc[revised, ["planner", "auditor"]].drop_duplicates())
    with new_figure(figsize=(6.4, 3.6)) as (figure, axes):
        ax = axes[0, 0]
        for label in sorted(set(labels)):
            chosen = steps.loc[revised][(labels == label).to_numpy()]
            colour, marker = style[label]
            ax.scatter(
                chosen["delta_cost"], chosen["delta_reward"], s=9, alpha=0.45, color=colour, marker=marker, label=label
            )
        ax.axhline(0.0, color="#555555", linewidth=0.8)
        ax.axvline(0.0, color="#555555", linewidth=0.8)
        ax.set_xlabel("Δ cost (final − ā)")
        ax.set_ylabel("Δ reward (final − ā)")
        ax.set_title(title)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), markerscale=2)
        caption = (
            "Each revision's counterfactual effect from the same state and price shock: left of the vertical line it "
            "lowered cost, below the horizontal line it lost reward (harmful when both cost was not lowered and "
            "reward was lost)."
        )
        return save_figure(figure, out_dir, key, title, caption)


def governance_figures(data: ReportData, options: ReportOptions, out_dir: Path) -> list[FigureFile | Skipped]:
    """The report's governance figures (skipped without counterfactual records)."""
    keys = (("governance_precision_recall", "Audit precision vs recall"), ("governance_revision_deltas", "Revisions"))
    if data.diagnostics.empty:
        return [Skipped(key, title, NO_DIAGNOSTICS) for key, title in keys]
    quality = report_audit_quality(data, options, group_by=("planner", "auditor"))
    steps = step_frame(
        data.diagnostics, harm_outcome=harm_outcome(data), steps_per_day=steps_per_day_of(data.task_spec)
    )
    return [precision_recall_figure(quality, out_dir), revision_scatter_figure(steps, data.diagnostics, out_dir)]


__all__ = ["governance_figures", "precision_recall_figure", "revision_scatter_figure"]
