"""Contrast tables of a task without a paper reference: what changing one setting does to each metric.

Every :class:`~solarchain_eval.evaluation.settings.Contrast` a setting declares (its
``compare_with``) whose two settings the run holds becomes rows of the table
``task_contrast_<kind>`` (``ablation``: the reward without its feasibility penalty against the
penalised one; ``governance``: behind the Planner/Auditor layer against without). Per policy
evaluated in both settings and per metric the task declares (grouped by template dimension): the
mean in the base setting, the mean in the treated setting, the difference treated − base with a
cluster-bootstrap interval, and the difference within each run seed (in a paper root a learned
policy's run seed is its training seed, so these show the spread over trainings).

Pairing. When a policy ran the same episodes in both settings (run seed, episode, episode seed
and start hour), the difference is the mean of per-rollout deltas matched as the paper's delta
tables match them (:func:`~solarchain_eval.report.statistics.paired_deltas`), and the bootstrap
resamples the deltas' clusters (:func:`~solarchain_eval.report.statistics.bootstrap_mean`; start
days by default), so a day that is hard in both settings cancels out. Otherwise it is
mean(treated) − mean(base) with both samples' clusters resampled jointly
(:func:`~solarchain_eval.report.statistics.bootstrap_mean_difference`), and a note says so.
The paper's market keeps its own delta tables; this module serves every other task.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from ..evaluation.settings import ABLATION_CONTRAST, GOVERNANCE_CONTRAST, Contrast, setting_pairs
from ..tasks.base import MetricSpec
from .figure_style import FigureFile, new_figure, policy_colour, save_figure
from .loading import ReportData
from .naming import paper_order
from .options import ReportOptions
from .statistics import SampleSize, bootstrap_mean, bootstrap_mean_difference, paired_deltas, sample_size
from .table_model import Column, ReportTable, Skipped, basis_sentence, fixed, text, with_interval
from .task_summary import _digits, metric_header, summary_metrics

#: The file stem of a kind's table: ``tables/task_contrast_<kind>.<fmt>``.
KEY_PREFIX = "task_contrast_"
#: The figure of the safety differences of the learned policies: ``figures/task_contrast_safety.<fmt>``.
FIGURE_KEY = "task_contrast_safety"
#: The episode a rollout ran; two settings ran the same episodes when a policy's sets of these agree.
EPISODE_COLUMNS = ["run_seed", "episode", "episode_seed", "start_hour"]
#: What the treated setting of a built-in contrast kind changes (a kind of one's own uses its meaning).
KIND_WORDS = {
    ABLATION_CONTRAST: "drops the reward's feasibility (physics) penalty",
    GOVERNANCE_CONTRAST: "adds the Planner/Auditor layer",
}
#: The mark of a difference whose interval excludes 0.
EXCLUDES_ZERO = "*"


def present_contrasts(data: ReportData) -> list[tuple[str, str, Contrast]]:
    """``(base, treated, contrast)`` of every registered contrast whose two settings the run holds."""
    present = data.settings
    return [(base, treated, c) for base, treated, c in setting_pairs(names=present) if base in present]


def _key(kind: str) -> str:
    return KEY_PREFIX + re.sub(r"[^A-Za-z0-9_-]", "_", kind)


def same_episodes(base: pd.DataFrame, treated: pd.DataFrame) -> bool:
    """Whether two settings' rollouts of one policy are the same episodes, each once (so they pair one to one)."""
    a = base[EPISODE_COLUMNS].sort_values(EPISODE_COLUMNS).to_numpy().tolist()
    b = treated[EPISODE_COLUMNS].sort_values(EPISODE_COLUMNS).to_numpy().tolist()
    return a == b and len({tuple(r) for r in a}) == len(a)


def _seed_means(frame: pd.DataFrame, metric: str) -> pd.Series:
    return frame.groupby("run_seed")[metric].mean()


def policy_differences(
    base: pd.DataFrame, treated: pd.DataFrame, metrics: list[str], options: ReportOptions
) -> tuple[list[dict], SampleSize, bool]:
    """One policy's differences treated − base for each metric.

    Parameters
    ----------
    base, treated
        The policy's ``metrics.csv`` rows in the base and in the treated setting.
    metrics
        The metric columns.

    Returns
    -------
    (rows, size, paired)
        Per metric a dict (``metric``, ``base_mean``, ``treated_mean``, ``difference``, ``low``,
        ``high``, ``excludes_zero``, ``run_seeds``, ``seed_differences``); the sample behind them
        (the matched pairs, or both settings' rollouts); whether the rollouts were paired.
    """
    paired = same_episodes(base, treated)
    cluster = options.cluster_by
    if paired:
        both = pd.concat([base, treated], ignore_index=True)
        deltas = paired_deltas(both, str(base["setting"].iloc[0]), str(treated["setting"].iloc[0]), metrics).frame
        size = sample_size(deltas)
    else:
        size = sample_size(pd.concat([base, treated], ignore_index=True))
    rows = []
    for metric in metrics:
        if paired:
            interval = bootstrap_mean(deltas[metric], deltas[cluster], **options.bootstrap())
            by_seed = _seed_means(deltas, metric)
        else:
            interval = bootstrap_mean_difference(
                treated[metric], treated[cluster], base[metric], base[cluster], **options.bootstrap()
            )
            by_seed = (_seed_means(treated, metric) - _seed_means(base, metric)).dropna()
        rows.append(
            {
                "metric": metric,
                "base_mean": float(base[metric].to_numpy(dtype=float).mean()),
                "treated_mean": float(treated[metric].to_numpy(dtype=float).mean()),
                "difference": interval.estimate,
                "low": interval.low,
                "high": interval.high,
                "excludes_zero": bool(interval.low > 0 or interval.high < 0),
                "run_seeds": [int(s) for s in by_seed.index],
                "seed_differences": [float(v) for v in by_seed.to_numpy()],
            }
        )
    return rows, size, paired


def contrast_frame(data: ReportData, options: ReportOptions) -> pd.DataFrame:
    """Every row of the contrast tables: per present contrast, policy in both settings and declared metric.

    Columns: ``kind``, ``comparison`` ("treated − base"), ``base``, ``treated``, ``policy``,
    ``dimension``, ``metric``, ``unit``, ``direction``, the figures of :func:`policy_differences`,
    ``paired``, ``n`` (pairs, or both settings' rollouts), ``distinct_episode_seeds`` and
    ``distinct_start_days``.
    """
    specs = [spec for group in summary_metrics(data.task_spec).values() for spec in group]
    by_name = {spec.name: spec for spec in specs}
    rows = []
    for base_name, treated_name, contrast in present_contrasts(data):
        base_rows, treated_rows = data.rollouts(base_name), data.rollouts(treated_name)
        shared = set(base_rows["policy"].astype(str)) & set(treated_rows["policy"].astype(str))
        for policy in paper_order(shared):
            base = base_rows[base_rows["policy"].astype(str) == policy]
            treated = treated_rows[treated_rows["policy"].astype(str) == policy]
            found, size, paired = policy_differences(base, treated, list(by_name), options)
            for row in found:
                spec: MetricSpec = by_name[row["metric"]]
                rows.append(
                    {
                        "kind": contrast.kind,
                        "comparison": f"{treated_name} − {base_name}",
                        "base": base_name,
                        "treated": treated_name,
                        "policy": policy,
                        "dimension": spec.dimension,
                        "metric": spec.name,
                        "unit": spec.unit,
                        "direction": spec.direction,
                        **row,
                        "paired": paired,
                        "n": size.n,
                        "distinct_episode_seeds": size.episode_seeds,
                        "distinct_start_days": size.start_days,
                    }
                )
    return pd.DataFrame(rows)


def _change(contrast: Contrast) -> str:
    """What the treated setting of ``contrast`` changes, in words."""
    if contrast.kind in KIND_WORDS:
        return f"the treated setting {KIND_WORDS[contrast.kind]}"
    return contrast.meaning or f"a {contrast.kind} contrast"


def _difference_cell(digits: dict[str, int]):
    def render(row) -> str:
        cell = with_interval(row["difference"], row["low"], row["high"], digits[row["metric"]])
        return f"{cell} {EXCLUDES_ZERO}" if row["excludes_zero"] else cell

    return render


def contrast_table(data: ReportData, options: ReportOptions, kind: str, frame: pd.DataFrame) -> ReportTable | Skipped:
    """The table ``task_contrast_<kind>`` from the rows of :func:`contrast_frame` (all kinds' rows)."""
    title = f"{kind.capitalize()} contrasts of task {data.task}"
    present = [(b, t, c) for b, t, c in present_contrasts(data) if c.kind == kind]
    if not present:
        wanted = ", ".join(f"{t} and {b}" for b, t, _ in setting_pairs(kind))
        held = ", ".join(data.settings) or "no setting"
        return Skipped(_key(kind), title, f"needs both settings of a {kind} contrast ({wanted}); the run has {held}")
    rows = frame[frame["kind"] == kind].reset_index(drop=True) if not frame.empty else frame
    if rows.empty:
        return Skipped(_key(kind), title, f"no policy was evaluated in both settings of a {kind} contrast")
    specs = {spec.name: spec for group in summary_metrics(data.task_spec).values() for spec in group}
    digits = {
        name: _digits(group[["base_mean", "treated_mean", "difference"]].to_numpy(dtype=float).ravel())
        for name, group in rows.groupby("metric")
    }
    columns = [
        Column("Comparison", text("comparison"), align="l"),
        Column("Policy", text("policy"), align="l"),
        Column("Dimension", text("dimension"), align="l"),
        Column("Metric", lambda r: metric_header(specs[r["metric"]]), align="l"),
        Column("Base", lambda r: fixed(r["base_mean"], digits[r["metric"]]), align="r"),
        Column("Treated", lambda r: fixed(r["treated_mean"], digits[r["metric"]]), align="r"),
        Column(f"Δ treated − base [{options.confidence:.0%} CI]", _difference_cell(digits), align="r"),
        Column(
            "Δ per run seed",
            lambda r: ", ".join(fixed(v, digits[r["metric"]]) for v in r["seed_differences"]),
            align="r",
        ),
    ]
    changes = "; ".join(f"{t} − {b}: {_change(c)}" for b, t, c in present)
    unpaired = rows[~rows["paired"]].drop_duplicates(["comparison", "policy"])
    notes = [
        f"{r['comparison']}, {r['policy']}: the two settings ran different episodes, so the difference is of "
        f"unpaired means and the interval resamples both samples' {options.cluster_by} clusters jointly."
        for r in unpaired.to_dict("records")
    ]
    per_group = rows.drop_duplicates(["comparison", "policy"])
    sizes = [
        SampleSize(int(r["n"]), int(r["distinct_episode_seeds"]), int(r["distinct_start_days"]))
        for r in per_group.to_dict("records")
    ]
    return ReportTable(
        key=_key(kind),
        label=f"tab:task-contrast-{kind}",
        title=title,
        caption=(
            f"Contrasts of kind {kind} the settings declare ({changes}), per policy evaluated in both settings and "
            f"per metric task {data.task} declares, grouped by dimension (↑ higher is better, ↓ lower is better, "
            f"· neither): the mean in the base setting, the mean in the treated setting, and the difference "
            f"treated − base [{options.confidence:.0%} cluster-bootstrap interval, resampling {options.cluster_by}; "
            f"rollouts are paired on run seed, episode, episode seed and start hour where both settings ran the "
            f"same episodes]. {EXCLUDES_ZERO} marks an interval that excludes 0. Δ per run seed: the difference "
            "within each run seed, in seed order (the seed spread; in a paper root a learned policy's run seed is "
            "its training seed)."
        ),
        columns=columns,
        data=rows.drop(columns="kind"),
        basis=basis_sentence(sizes, "paired rollouts" if bool(rows["paired"].all()) else "rollouts"),
        notes=notes,
    )


def task_contrast_tables(
    data: ReportData, options: ReportOptions, frame: pd.DataFrame | None = None
) -> list[ReportTable | Skipped]:
    """One table per registered contrast kind (made, or skipped with the reason); ``frame``: a
    :func:`contrast_frame` already computed (computed here when None)."""
    frame = contrast_frame(data, options) if frame is None else frame
    kinds = dict.fromkeys(c.kind for _, _, c in setting_pairs())
    return [contrast_table(data, options, kind, frame) for kind in kinds]


def task_contrast_figure(
    data: ReportData, options: ReportOptions, out_dir: Path, frame: pd.DataFrame | None = None
) -> FigureFile | Skipped:
    """Per learned policy and present contrast, the difference of each declared safety metric with its interval."""
    title = "Safety differences of the learned policies"
    frame = contrast_frame(data, options) if frame is None else frame
    specs = summary_metrics(data.task_spec).get("safety", ())
    if not specs:
        return Skipped(FIGURE_KEY, title, f"task {data.task!r} declares no safety metric")
    baselines = set(data.task_spec.baselines())  # the task's rule baselines are not learned
    learned = ~frame["policy"].isin(baselines) if not frame.empty else None
    rows = frame[frame["dimension"].eq("safety") & learned] if not frame.empty else frame
    if rows.empty:
        return Skipped(FIGURE_KEY, title, "no learned policy was evaluated in both settings of a declared contrast")
    groups = list(dict.fromkeys(zip(rows["comparison"], rows["policy"], strict=True)))
    policies = sorted({p for _, p in groups})
    with new_figure(1, len(specs), figsize=(3.0 * len(specs) + 1.6, 0.32 * len(groups) + 1.3), sharey=True) as (
        figure,
        axes,
    ):
        for ax, spec in zip(axes[0], specs, strict=True):
            of_metric = rows[rows["metric"] == spec.name].set_index(["comparison", "policy"])
            for y, group in enumerate(groups):
                row = of_metric.loc[group]
                error = np.array([[row["difference"] - row["low"]], [row["high"] - row["difference"]]])
                colour = policy_colour(group[1], policies)
                face = colour if row["excludes_zero"] else "white"
                ax.errorbar(row["difference"], y, xerr=error, fmt="o", color=colour, mfc=face, capsize=2.5)
            ax.axvline(0.0, color="black", linewidth=0.8)
            ax.set_title(metric_header(spec))
            ax.set_xlabel(f"Δ treated − base ({spec.unit})")
        axes[0][0].set_yticks(range(len(groups)))
        axes[0][0].set_yticklabels([f"{policy} ({comparison})" for comparison, policy in groups])
        axes[0][0].invert_yaxis()
        caption = (
            f"Difference treated − base of each safety metric task {data.task} declares, per learned policy and "
            f"contrast, with its {options.confidence:.0%} cluster-bootstrap interval (resampling {options.cluster_by}; "
            "paired rollouts where both settings ran the same episodes). Filled: the interval excludes 0. The "
            "numbers are in the task_contrast_<kind> tables."
        )
        return save_figure(figure, out_dir, FIGURE_KEY, title, caption)


__all__ = [
    "EPISODE_COLUMNS",
    "EXCLUDES_ZERO",
    "FIGURE_KEY",
    "KEY_PREFIX",
    "contrast_frame",
    "contrast_table",
    "policy_differences",
    "present_contrasts",
    "same_episodes",
    "task_contrast_figure",
    "task_contrast_tables",
]
