"""Governance diagnostics figures: precision vs recall per auditor, Δcost vs Δreward per revision."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..governance import audit_quality, step_frame
from ..loading import ReportData
from ..options import ReportOptions
from ..tables.governance import NO_DIAGNOSTICS
from ..tables.model import Skipped
from .style import EXTRA_COLOURS, FigureFile, new_figure, save_figure


def _label(row: pd.Series | dict) -> str:
    return f"{row['planner']} / {row['auditor']}"


def _colours(labels: list[str]) -> dict[str, str]:
    return {label: EXTRA_COLOURS[i % len(EXTRA_COLOURS)] for i, label in enumerate(sorted(set(labels)))}


def precision_recall_figure(
    quality: pd.DataFrame, out_dir: Path, key: str = "governance_precision_recall"
) -> FigureFile:
    """One point per (planner, auditor) row with its bootstrap intervals; the unsafe share is the
    precision a chance auditor reaches (dotted line)."""
    title = "Audit precision vs recall"
    labels = [_label(row) for _, row in quality.iterrows()]
    colours = _colours(labels)
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for label, (_, row) in zip(labels, quality.iterrows(), strict=True):
            x, y = row["recall"], row["precision"]
            xerr = [[max(x - row["recall_low"], 0)], [max(row["recall_high"] - x, 0)]]
            yerr = [[max(y - row["precision_low"], 0)], [max(row["precision_high"] - y, 0)]]
            ax.errorbar(x, y, xerr=xerr, yerr=yerr, fmt="o", color=colours[label], label=label, capsize=2)
        ax.axhline(float(quality["unsafe_share"].mean()), color="#555555", linestyle=":", linewidth=1)
        ax.set_xlim(-0.02, 1.02)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("Recall (unsafe steps audited)")
        ax.set_ylabel("Precision (audited steps unsafe)")
        ax.set_title(title)
        ax.legend(loc="lower left")
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
    colours = _colours(list(labels))
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        for label in sorted(set(labels)):
            chosen = steps.loc[revised][(labels == label).to_numpy()]
            ax.scatter(
                chosen["delta_cost"], chosen["delta_reward"], s=8, alpha=0.5, color=colours[label], label=label, lw=0
            )
        ax.axhline(0.0, color="#555555", linewidth=0.8)
        ax.axvline(0.0, color="#555555", linewidth=0.8)
        ax.set_xlabel("Δ cost (final − ā)")
        ax.set_ylabel("Δ reward (final − ā)")
        ax.set_title(title)
        ax.legend(loc="best", markerscale=2)
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
    quality = audit_quality(
        data.diagnostics, group_by=("planner", "auditor"), n_resamples=options.n_resamples, seed=options.seed
    )
    steps = step_frame(data.diagnostics)
    return [precision_recall_figure(quality, out_dir), revision_scatter_figure(steps, data.diagnostics, out_dir)]


__all__ = ["governance_figures", "precision_recall_figure", "revision_scatter_figure"]
