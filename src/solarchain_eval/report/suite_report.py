"""The report of a suite root (``report ROOT`` on ``evaluate --suite --out ROOT``; docs/suites.md).

From the verified suite root (:func:`~.suite_loading.load_suite_data`) it writes, atomically, as
every report output is written:

- ``tables/suite_entries.*``: per entry (and its split), each policy's mean normalised score;
- ``tables/suite_aggregates.*``: per policy, rliable's IQM, mean, median and optimality gap of the
  normalised scores with their 95 % stratified-bootstrap intervals
  (:func:`~solarchain_eval.evaluation.suite_stats.aggregate_table`), best IQM first;
- ``tables/suite_improvement.*``: P(row > column) for every pair of policies;
- ``figures/suite_profile.png``/``.svg``: the performance profile;
- ``figures/suite_heatmap.png``/``.svg``: mean normalised score per policy and entry;
- ``report.md`` and a self-contained ``index.html``.

The intervals use the suite's own bootstrap seed (recorded in ``suite_metadata.json``) and
``--resamples`` resamples, so with the default 2,000 they equal those ``evaluate --suite`` printed.
"""

from __future__ import annotations

import html
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..common.atomic_files import atomic_write_text
from ..evaluation.suite_stats import AGGREGATE_NAMES, aggregate_table, draw_performance_profile, improvement_table
from ..experiments.layout import REPORT_DIR
from .figure_style import FigureFile, new_figure, policy_colour, save_figure
from .loading import load_report_data
from .naming import policy_label
from .options import ReportOptions
from .outputs import INDEX_FILE, MARKDOWN_FILE, ReportOutcome, write_tables
from .paper.html import CSS, figure_html
from .suite_loading import SuiteData, load_suite_data
from .table_model import Column, ReportTable, fixed, text, to_html, to_markdown, with_interval

#: The suite report's table and figure keys.
ENTRIES, AGGREGATES, IMPROVEMENT = "suite_entries", "suite_aggregates", "suite_improvement"
PROFILE, HEATMAP = "suite_profile", "suite_heatmap"
_HEADERS = {"iqm": "IQM", "mean": "Mean", "median": "Median", "optimality_gap": "Optimality gap"}


def _basis(data: SuiteData) -> str:
    episodes = len(data.scores[["run_seed", "episode"]].drop_duplicates())
    return (
        f"Per policy: {len(data.entries)} entries × {episodes} episodes (run seeds × episodes); normalised per "
        f"entry on its own {data.reference[0]} (0) and {data.reference[1]} (1)."
    )


def _value(name: str, digits: int = 3) -> Callable[[dict], str]:
    return lambda row: fixed(row[name], digits)


def entries_table(data: SuiteData, policies: Sequence[str]) -> ReportTable:
    """Per entry: each policy's mean normalised score (the CSV adds each mean raw score, ``<policy>_score``)."""
    means = data.scores.groupby(["entry", "split", "policy"], sort=False)[["score", "normalised"]].mean()
    rows = []
    for entry in data.entries:
        row: dict = {"entry": entry["name"], "split": entry["split"]}
        for policy in policies:
            row[policy] = float(means.loc[(entry["name"], entry["split"], policy), "normalised"])
            row[f"{policy}_score"] = float(means.loc[(entry["name"], entry["split"], policy), "score"])
        rows.append(row)
    columns = [Column("Entry", text("entry"), align="l"), Column("Split", text("split"), align="l")]
    columns += [Column(policy_label(p), _value(p), align="r") for p in policies]
    return ReportTable(
        ENTRIES,
        "tab:suite-entries",
        f"Normalised score per entry (suite {data.suite})",
        f"Mean normalised score of each policy on each entry of suite {data.suite} (0: {data.reference[0]}, "
        f"1: {data.reference[1]}, on the entry's own runs).",
        columns,
        pd.DataFrame(rows),
        _basis(data),
    )


def aggregates_table(data: SuiteData, aggregates: pd.DataFrame, resamples: int) -> ReportTable:
    """Per policy: the suite aggregates with their stratified-bootstrap intervals, best IQM first."""

    def interval(name: str) -> Callable[[dict], str]:
        return lambda row: with_interval(row[name], row[f"{name}_low"], row[f"{name}_high"], 3)

    columns = [Column("Policy", lambda row: policy_label(str(row["policy"])), align="l")]
    columns += [Column(f"{_HEADERS[name]} [95% CI]", interval(name), align="r") for name in AGGREGATE_NAMES]
    return ReportTable(
        AGGREGATES,
        "tab:suite-aggregates",
        f"Suite aggregates (suite {data.suite}, split {', '.join(data.splits)})",
        "IQM (rliable's interquartile mean of every normalised score), mean and median of the per-entry means, "
        "and optimality gap (1 minus the mean score clipped at 1; lower is better), with 95 % percentile "
        f"intervals of a stratified bootstrap ({resamples} resamples of every entry's episodes, seed "
        f"{data.bootstrap_seed}). Best IQM first.",
        columns,
        aggregates.reset_index(drop=True),
        _basis(data),
        notes=[f"Suite protocol id {data.protocol_id}: suite results are comparable when their ids are equal."],
    )


def improvement_matrix(data: SuiteData, matrices: dict[str, np.ndarray], policies: Sequence[str]) -> ReportTable:
    """P(row > column) for every pair of policies, averaged over entries."""
    pairs = {(r["policy"], r["over"]): r["probability"] for r in improvement_table(matrices)}
    frame = pd.DataFrame([{"policy": x, **{y: pairs.get((x, y), float("nan")) for y in policies}} for x in policies])
    columns = [Column("P(row > column)", lambda row: policy_label(str(row["policy"])), align="l")]
    columns += [
        Column(policy_label(y), lambda row, y=y: "–" if row["policy"] == y else fixed(row[y], 3), align="r")
        for y in policies
    ]
    return ReportTable(
        IMPROVEMENT,
        "tab:suite-improvement",
        "Probability of improvement",
        "P(X > Y): per entry, the share of (episode of X, episode of Y) pairs where X scores more (ties count "
        "half), averaged over entries; 0.5 means no better.",
        columns,
        frame,
        _basis(data),
    )


def profile_figure(data: SuiteData, matrices: dict[str, np.ndarray], out_dir: Path) -> FigureFile:
    """The performance profile (:func:`~solarchain_eval.evaluation.suite_stats.draw_performance_profile`)."""
    colours = {p: policy_colour(p, list(matrices)) for p in matrices}
    with new_figure(figsize=(6.0, 4.0)) as (figure, axes):
        draw_performance_profile(axes[0, 0], matrices, colours)
        axes[0, 0].set_title(f"suite {data.suite}: performance profile")
        return save_figure(
            figure,
            out_dir,
            PROFILE,
            "Performance profile",
            "For each threshold τ, the fraction of each policy's normalised scores (every entry and episode) "
            "above τ; dotted lines at the reference levels 0 and 1.",
        )


def heatmap_figure(data: SuiteData, table: ReportTable, policies: Sequence[str], out_dir: Path) -> FigureFile:
    """Mean normalised score per policy (rows) and entry (columns), each cell annotated."""
    values = table.data[list(policies)].to_numpy(float).T  # policies x entries
    names = [str(e) for e in table.data["entry"]]
    width = max(5.2, 0.75 * len(names) + 2.2)
    with new_figure(figsize=(width, 0.5 * len(policies) + 1.8)) as (figure, axes):
        ax = axes[0, 0]
        image = ax.imshow(values, cmap="viridis", aspect="auto")
        ax.grid(False)
        ax.set_xticks(range(len(names)), names, rotation=45, ha="right")
        ax.set_yticks(range(len(policies)), [policy_label(p) for p in policies])
        middle = float(np.nanmean(values)) if values.size else 0.0
        for i in range(values.shape[0]):
            for j in range(values.shape[1]):
                colour = "black" if values[i, j] > middle else "white"
                ax.text(j, i, fixed(values[i, j], 2), ha="center", va="center", fontsize=7, color=colour)
        figure.colorbar(image, ax=ax, label="mean normalised score")
        ax.set_title(f"suite {data.suite}: normalised score per entry")
        return save_figure(
            figure,
            out_dir,
            HEATMAP,
            "Normalised score per entry",
            f"Mean normalised score of each policy on each entry (0: {data.reference[0]}, 1: {data.reference[1]}).",
        )


def _markdown(
    data: SuiteData, tables: Sequence[ReportTable], figures: Sequence[FigureFile], warnings: Sequence[str]
) -> str:
    lines = [f"# SolarChain-Eval suite report: {data.root}", ""]
    lines += [
        f"Suite `{data.suite}`, split {', '.join(data.splits)}, suite protocol id `{data.protocol_id}`, "
        f"setting `{data.setting}`, {len(data.entries)} entries.",
        "",
    ]
    lines += [f"> **Warning.** {w}\n" for w in warnings]
    lines += ["## Tables", ""] + [to_markdown(t) for t in tables]
    lines += ["## Figures", ""] + [f"![{f.title}](figures/{f.key}.png)\n\n*{f.caption}*\n" for f in figures]
    return "\n".join(lines)


def _html(
    data: SuiteData, tables: Sequence[ReportTable], figures: Sequence[FigureFile], warnings: Sequence[str]
) -> str:
    escape = html.escape
    body = [
        "<h1>SolarChain-Eval suite report</h1>",
        f'<p class="meta">Source: <code>{escape(str(data.root))}</code>: suite <code>{escape(data.suite)}</code>, '
        f"split {escape(', '.join(data.splits))}, suite protocol id <code>{escape(data.protocol_id)}</code>, "
        f"setting <code>{escape(data.setting)}</code>, {len(data.entries)} entries.</p>",
        *[f'<div class="warning"><strong>Warning.</strong> {escape(w)}</div>' for w in warnings],
        "<h2>Tables</h2>",
        *[to_html(t) for t in tables],
        '<h2 id="figures">Figures</h2>',
        '<div class="figures">' + "".join(figure_html(f) for f in figures) + "</div>",
    ]
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n<link rel="icon" href="data:,">\n'
        f"<title>SolarChain-Eval suite report: {escape(data.root.name)}</title>\n<style>{CSS}</style>\n</head>\n"
        "<body>\n" + "\n".join(body) + "\n</body>\n</html>\n"
    )


def build_suite_report(
    root: Path,
    out_dir: Path | None = None,
    *,
    formats: Sequence[str],
    options: ReportOptions = ReportOptions(),
    figures: bool = True,
    allow_unverified: bool = False,
) -> ReportOutcome:
    """Write the report of the suite root ``root`` (see the module docstring) into ``out_dir``
    (default ``root/report``). ``allow_unverified`` reports entry runs whose files their metadata
    does not vouch for, with a warning each; the suite root's own files are always checked.

    Raises
    ------
    ReportDataError
        A file of the root or of an entry's run is missing, malformed or not vouched for.
    """
    data = load_suite_data(root, read_run=lambda path: load_report_data(path, allow_unverified=allow_unverified))
    out = Path(out_dir) if out_dir is not None else Path(root) / REPORT_DIR
    matrices = data.matrices()
    aggregates = pd.DataFrame(aggregate_table(matrices, reps=options.n_resamples, seed=data.bootstrap_seed))
    aggregates = aggregates.sort_values(["iqm", "policy"], ascending=[False, True], kind="stable")
    policies = [str(p) for p in aggregates["policy"]]  # best IQM first
    per_entry = entries_table(data, policies)
    tables = [
        per_entry,
        aggregates_table(data, aggregates, options.n_resamples),
        improvement_matrix(data, matrices, policies),
    ]
    drawn = (
        [profile_figure(data, matrices, out / "figures"), heatmap_figure(data, per_entry, policies, out / "figures")]
        if figures
        else []
    )
    warnings = [f"UNVERIFIED INPUT: {p}" for run in data.runs.values() for p in run.unverified]
    outcome = ReportOutcome(out_dir=out, data=data, tables=list(tables), figures=list(drawn), warnings=warnings)  # type: ignore[arg-type]
    outcome.files += [p for f in drawn for p in (f.png, f.svg)]
    outcome.files += write_tables(out, tables, formats)
    if "md" in formats:
        outcome.files.append(atomic_write_text(out / MARKDOWN_FILE, _markdown(data, tables, drawn, warnings)))
    if "html" in formats:
        outcome.files.append(atomic_write_text(out / INDEX_FILE, _html(data, tables, drawn, warnings)))
    return outcome
