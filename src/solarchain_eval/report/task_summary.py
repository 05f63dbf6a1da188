"""The report's generic tables: a task's declared metrics, one table per template dimension.

Every column comes from the task's declarations (:attr:`~solarchain_eval.tasks.base.Task.metrics`):
its name, unit and direction (↑ higher is better, ↓ lower is better, · neither). A task without a
paper reference gets one table per dimension (utility, safety, stability, fairness, auditability)
in place of the paper's tables; a task with one (the solar market) keeps the paper's tables, and
a table here shows each dimension's declared metrics the paper's tables do not cover (none today).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pandas as pd

from ..tasks.base import DIMENSIONS, MetricSpec, Task, paper_reference_of
from .loading import ReportData
from .naming import paper_order
from .options import ReportOptions
from .statistics import bootstrap_mean, mean_std, sample_size
from .table_model import Column, ReportTable, Row, Skipped, basis_sentence, fixed, integer, pm, text

#: How a header shows a metric's direction.
ARROWS = {"higher": "↑", "lower": "↓", "none": "·"}
#: The file stem of a dimension's table: ``tables/task_<dimension>.<fmt>``.
KEY_PREFIX = "task_"
#: What the report says in place of the paper's tables and figures for a task without a paper reference.
NO_PAPER = (
    "the paper's tables and figures are the solar market's; task {task!r} has no paper reference, so the "
    "report shows its declared metrics by template dimension (tables task_<dimension>) and what each declared "
    "setting contrast changes in them (tables task_contrast_<kind>)"
)


def metric_header(spec: MetricSpec) -> str:
    """``name (unit) arrow``: how the report and the board head a declared metric's column."""
    return f"{spec.name} ({spec.unit}) {ARROWS[spec.direction]}"


def summary_metrics(task: Task) -> dict[str, tuple[MetricSpec, ...]]:
    """The declared metrics the generic tables show, by dimension (in :data:`DIMENSIONS` order).

    Every declared metric of a task without a paper reference; for a task with one, those its
    paper's tables do not cover (dimensions without any are left out).
    """
    paper = paper_reference_of(task)
    covered = set(paper.metrics) if paper is not None else set()
    shown = {d: tuple(m for m in task.metrics if m.dimension == d and m.name not in covered) for d in DIMENSIONS}
    return shown if paper is None else {d: specs for d, specs in shown.items() if specs}


def _digits(values: np.ndarray) -> int:
    """Decimals that keep a column readable: fewer for large magnitudes."""
    finite = np.abs(values[np.isfinite(values)])
    largest = float(finite.max()) if finite.size else 0.0
    return 2 if largest >= 100 else 3 if largest >= 1 else 4


def _cell(name: str, digits: int) -> Callable[[Row], str]:
    """Formatter of ``mean ± std [low, high]`` of a metric."""

    def render(row: Row) -> str:
        interval = f"{fixed(row[f'{name}_low'], digits)}, {fixed(row[f'{name}_high'], digits)}"
        return f"{pm(row[f'{name}_mean'], row[f'{name}_std'], digits)} [{interval}]"

    return render


def dimension_table(
    data: ReportData, options: ReportOptions, dimension: str, specs: Sequence[MetricSpec]
) -> ReportTable | Skipped:
    """One dimension's table: per setting and policy, each metric's mean ± std and its interval."""
    title = f"{dimension.capitalize()} metrics of task {data.task}"
    key = f"{KEY_PREFIX}{dimension}"
    if not specs:
        return Skipped(key, title, f"task {data.task!r} declares no {dimension} metric")
    rows, sizes = [], []
    for setting in data.settings:
        in_setting = data.rollouts(setting)
        for policy in paper_order(in_setting["policy"].astype(str)):
            group = in_setting[in_setting["policy"].astype(str) == policy]
            row = {"setting": setting, "policy": policy, "n": len(group)}
            clusters = group[options.cluster_by].to_numpy()
            for spec in specs:
                values = group[spec.name].to_numpy(dtype=float)
                mean, std = mean_std(values)
                interval = bootstrap_mean(values, clusters, **options.bootstrap())
                row |= {f"{spec.name}_mean": mean, f"{spec.name}_std": std}
                row |= {f"{spec.name}_low": interval.low, f"{spec.name}_high": interval.high}
            rows.append(row)
            sizes.append(sample_size(group))
    frame = pd.DataFrame(rows)
    columns = [
        Column("Setting", text("setting"), align="l"),
        Column("Policy", text("policy"), align="l"),
        Column("Rollouts", integer("n"), align="r"),
    ]
    for spec in specs:
        digits = _digits(frame[f"{spec.name}_mean"].to_numpy(dtype=float))
        columns.append(Column(metric_header(spec), _cell(spec.name, digits)))
    level = f"{options.confidence:.0%}"
    meanings = "; ".join(f"{spec.name}: {spec.column.meaning} ({spec.unit})" for spec in specs)
    return ReportTable(
        key=key,
        label=f"tab:task-{dimension}",
        title=title,
        caption=(
            f"The {dimension} metrics task {data.task} declares, per setting and policy: mean ± sample standard "
            f"deviation (ddof=1) [{level} cluster-bootstrap interval of the mean, resampling {options.cluster_by}]. "
            f"↑ higher is better, ↓ lower is better, · neither. {meanings}."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes, "rollouts"),
    )


def task_summary_tables(data: ReportData, options: ReportOptions) -> list[ReportTable | Skipped]:
    """The generic tables of the run's task (see the module docstring), in :data:`DIMENSIONS` order."""
    return [dimension_table(data, options, d, specs) for d, specs in summary_metrics(data.task_spec).items()]
