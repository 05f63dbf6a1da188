"""Checking a run against the paper: each published cell beside the run's estimate, with a verdict.

For every cell of the paper's main table, the learned policies' differences to the heuristics,
the physics-ablation deltas and the RL+LLM rows, the paper's printed value stands beside the
run's value and a verdict:

``equal``
    a deterministic row (a rule baseline without the Planner/Auditor layer): every printed
    digit of the run's cell, rounded to the paper's decimals, equals the paper's; else ``differs``;
``inside`` / ``outside``
    a learned row: whether the paper's value, widened by its rounding (half a unit of its last
    digit; one unit for a difference of two printed values), meets the run's start-day
    cluster-bootstrap interval of the mean;
``stand-in: ...``
    a row of an agentic setting the run governed with a stand-in (a rule or other non-LLM
    planner or auditor, or the local model) instead of the hosted LLM: never compared;
``not in run``
    the run has no rollouts (or columns) for the cell.

The paper's findings are checked too (``holds`` / ``flips``), with the share of training-seed
resamples on which each still holds (:mod:`~solarchain_eval.report.against_paper.seed_spread`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from ...evaluation.settings import SETTING_AGENTIC, SETTING_AGENTIC_NO_PHYSICS, SETTING_MAIN
from ..loading import ReportData
from ..naming import policy_label
from ..options import AGAINST_CHOICES as AGAINST_CHOICES
from ..options import ReportOptions
from ..statistics import Interval, mean_std
from ..table_model import Column, ReportTable, Skipped, fixed, pm, text, with_interval
from .against_findings import findings_table
from .paper_estimates import NOT_IN_RUN, Estimate, RunEstimates, difference, is_agentic, is_deterministic, stand_in
from .paper_reference import Ref, metric_better, paper_value, ref_of, table_values
from .seed_spread import draw_seeds, seed_ranking_table, seed_spread_table

#: The keys of every table the check writes (``tables/<key>.{md,tex,csv}``).
AGAINST_KEYS = (
    "against_paper_main",
    "against_paper_contrasts",
    "against_paper_ablation",
    "against_paper_agentic",
    "against_paper_findings",
    "seed_spread",
    "seed_rankings",
)
LEARNED = ("ppo", "sac", "dqn")
HEURISTICS = ("static", "random", "myopic")


@dataclass(frozen=True)
class Check:
    """One published cell beside the run's estimate (a row of an against-paper table)."""

    table: str
    row: str
    column: str
    paper: str
    paper_value: float
    decimals: int
    run: str
    estimate: float
    low: float
    high: float
    verdict: str


def against_verdict(paper: float, slack: float, interval: Interval) -> str:
    """``inside`` when [paper - slack, paper + slack] meets the interval, else ``outside``."""
    if np.isnan(interval.low) or np.isnan(interval.high):
        return "inside" if abs(interval.estimate - paper) <= slack else "outside"
    return "inside" if paper + slack >= interval.low and paper - slack <= interval.high else "outside"


def _display(header: str) -> str:
    return header.replace("$\\Delta$ ", "Δ ")


class _Checker:
    """Builds checks for one run (estimates, the stand-in label and options in one place)."""

    def __init__(self, data: ReportData, options: ReportOptions, estimates: RunEstimates) -> None:
        self.data, self.options, self.estimates = data, options, estimates
        self.stand_in = stand_in(data)

    def _stochastic(self, estimate: Estimate, paper: float, decimals: int, slack: float, ref: Ref):
        interval = estimate.interval(self.options)
        shown = with_interval(interval.estimate, interval.low, interval.high, decimals)
        if is_agentic(ref) and self.stand_in:
            return shown, interval, f"stand-in: {self.stand_in}"
        return shown, interval, against_verdict(paper, slack, interval)

    def cell(self, value_id: str) -> Check:
        """The check of one published cell (its ``mean``/``value`` id; a ``std`` beside it is shown too)."""
        row, ref = paper_value(value_id), ref_of(value_id)
        std_id = value_id.removesuffix(":mean") + ":std"
        std = paper_value(std_id) if value_id.endswith(":mean") and _exists(std_id) else None
        paper = row["printed"] + (f" ± {std['printed']}" if std else "")
        where = dict(table=row["table"], row=" / ".join(row["row"]), column=_display(row["column"]), paper=paper)
        where |= dict(paper_value=row["value"], decimals=row["decimals"])
        estimate = self.estimates.get(ref)
        if estimate is None:
            return Check(**where, run=NOT_IN_RUN, estimate=np.nan, low=np.nan, high=np.nan, verdict=NOT_IN_RUN)
        decimals = row["decimals"]
        if is_deterministic(ref):
            value = estimate.value
            shown = fixed(value, decimals) + (f" ± {fixed(self.estimates.std(ref), decimals)}" if std else "")
            verdict = "equal" if shown == paper else "differs"
            return Check(**where, run=shown, estimate=value, low=np.nan, high=np.nan, verdict=verdict)
        shown, interval, verdict = self._stochastic(estimate, row["value"], decimals, 0.5 * 10.0**-decimals, ref)
        return Check(
            **where, run=shown, estimate=interval.estimate, low=interval.low, high=interval.high, verdict=verdict
        )

    def contrast(self, minuend_id: str, subtrahend_id: str) -> Check:
        """The check of a difference of two published values (e.g. PPO minus the best heuristic)."""
        a, b = paper_value(minuend_id), paper_value(subtrahend_id)
        decimals = max(a["decimals"], b["decimals"])
        paper_delta = round(a["value"] - b["value"], decimals)
        names = [policy_label(r["policy"]) if "+" not in r["policy"] else _pooled_label(r["policy"]) for r in (a, b)]
        where = dict(table=a["table"], row=f"{names[0]} - {names[1]}", column=_metric_header(a["metric"]))
        where |= dict(paper=fixed(paper_delta, decimals), paper_value=paper_delta, decimals=decimals)
        first, second = self.estimates.get(ref_of(minuend_id)), self.estimates.get(ref_of(subtrahend_id))
        if first is None or second is None:
            return Check(**where, run=NOT_IN_RUN, estimate=np.nan, low=np.nan, high=np.nan, verdict=NOT_IN_RUN)
        # two printed values, each rounded: the difference is uncertain by one unit of the last digit
        shown, interval, verdict = self._stochastic(
            difference(first, second), paper_delta, decimals, 10.0**-decimals, ref_of(minuend_id)
        )
        return Check(
            **where, run=shown, estimate=interval.estimate, low=interval.low, high=interval.high, verdict=verdict
        )


def _exists(value_id: str) -> bool:
    try:
        paper_value(value_id)
    except KeyError:
        return False
    return True


def _pooled_label(policy: str) -> str:
    return "+".join(policy_label(p) for p in policy.split("+"))


def _metric_header(metric: str) -> str:
    headers = table_values("tab:main-performance", "mean").drop_duplicates("metric").set_index("metric")["column"]
    return str(headers.get(metric, metric))


# ----------------------------------------------------------------------------- the blocks


def main_ids() -> list[str]:
    """Mean ids of the main table, row by row."""
    return list(table_values("tab:main-performance", "mean")["id"])


def contrast_ids() -> list[tuple[str, str]]:
    """(learned, best heuristic) mean ids per metric, the heuristic best by the paper's values; then
    the text's pooled learned-vs-heuristics reward."""
    means = table_values("tab:main-performance", "mean")
    pairs = []
    for metric, sign in ((m, 1.0 if b == "higher" else -1.0) for m, b in metric_better().items()):
        in_metric = means[means["metric"] == metric].set_index("policy")
        best = max(HEURISTICS, key=lambda p: sign * in_metric.loc[p, "value"])
        pairs += [(in_metric.loc[p, "id"], in_metric.loc[best, "id"]) for p in LEARNED]
    return pairs + [("text:rl-pooled-reward", "text:heuristics-pooled-reward")]


def ablation_ids() -> list[str]:
    return list(table_values("tab:physics-ablation-deltas", "mean")["id"])


def agentic_ids() -> list[str]:
    """The RL+LLM cells: the layer's paired effects with audit and revision rates, the no-physics
    audit and revision rates, and the RL+LLM rows of the four-setting table."""
    effects = table_values("tab:auditability")
    ops = table_values("tab:app-llm-ops")
    ops = ops[(ops["setting"] == SETTING_AGENTIC_NO_PHYSICS) & ops["metric"].isin(["audit_rate", "revision_rate"])]
    learned = table_values("tab:app-four-setting-learned")
    learned = learned[
        learned["setting"].isin([SETTING_AGENTIC, SETTING_AGENTIC_NO_PHYSICS]) & (learned["statistic"] == "mean")
    ]
    return [i for frame in (effects, ops, learned) for i in frame["id"] if not i.endswith(":std")]


# ----------------------------------------------------------------------------- tables

VERDICTS_NOTE = (
    "Verdicts: equal / differs (a rule baseline: every printed digit after rounding to the paper's decimals); "
    "inside / outside (the paper's value, widened by its rounding, against the run's interval); "
    "stand-in (an agentic row governed by a stand-in for the paper's hosted LLM, not compared); not in run."
)


def _interval_basis(options: ReportOptions) -> str:
    return (
        f"Run: mean [{options.confidence:.0%} percentile bootstrap interval over {options.cluster_by} clusters, "
        f"{options.n_resamples} resamples, seed {options.seed}]."
    )


def checks_table(key: str, title: str, caption: str, checks: list[Check], options: ReportOptions) -> ReportTable:
    """A table of checks (CSV: every field of :class:`Check`)."""
    frame = pd.DataFrame([asdict(c) for c in checks])
    columns = [
        Column("Paper table", text("table"), align="l"),
        Column("Row", text("row"), align="l"),
        Column("Metric", text("column"), align="l"),
        Column("Paper", text("paper")),
        Column("Run", text("run")),
        Column("Verdict", text("verdict"), align="l"),
    ]
    counts = frame["verdict"].map(lambda v: "stand-in" if v.startswith("stand-in") else v).value_counts()
    summary = ", ".join(f"{n} {verdict}" for verdict, n in sorted(counts.items()))
    return ReportTable(
        key=key,
        label=f"tab:{key.replace('_', '-')}",
        title=title,
        caption=caption,
        columns=columns,
        data=frame,
        basis=f"{_interval_basis(options)} Verdicts: {summary}.",
        notes=[VERDICTS_NOTE],
    )


def check_tables(data: ReportData, options: ReportOptions, estimates: RunEstimates | None = None) -> list[ReportTable]:
    """The four tables of published cells beside the run's estimates."""
    checker = _Checker(data, options, estimates or RunEstimates(data.metrics))
    return [
        checks_table(
            "against_paper_main",
            "Main table against the paper",
            "Every cell of the paper's main table (mean ± std over rollouts) beside the run's.",
            [checker.cell(i) for i in main_ids()],
            options,
        ),
        checks_table(
            "against_paper_contrasts",
            "Learned policies minus the best heuristic, against the paper",
            "Each learned policy minus the heuristic baseline the paper shows best in that metric (differences of "
            "the main table's printed means), and the learned policies pooled minus the heuristics pooled "
            "(the text's cumulative rewards).",
            [checker.contrast(a, b) for a, b in contrast_ids()],
            options,
        ),
        checks_table(
            "against_paper_ablation",
            "Physics-ablation deltas against the paper",
            "Paired no-physics minus physics-penalised deltas, without (RL) and with (RL+LLM) the governance layer.",
            [checker.cell(i) for i in ablation_ids()],
            options,
        ),
        checks_table(
            "against_paper_agentic",
            "RL+LLM rows against the paper",
            "Paired effects of the Planner/Auditor layer, its audit and revision rates, and the RL+LLM rows of "
            "the four-setting summaries.",
            [checker.cell(i) for i in agentic_ids()],
            options,
        ),
    ]


def against_paper_tables(data: ReportData, options: ReportOptions) -> list[ReportTable | Skipped]:
    """Every against-paper table: the four of published cells, the findings, and the training-seed spread."""
    draws = (
        draw_seeds(data.metrics, n_resamples=options.n_resamples, seed=options.seed) if data.kind == "paper" else None
    )
    estimates = RunEstimates(data.metrics)  # shared, so that each quantity is computed once
    return [
        *check_tables(data, options, estimates),
        findings_table(data, options, draws, estimates),
        seed_spread_table(data, options),
        seed_ranking_table(data, options, draws, estimates),
    ]


# ----------------------------------------------------------------------------- the baselines of `run`


@dataclass(frozen=True)
class BaselineComparison:
    """The rule baselines' main-table cells beside the paper's.

    Attributes
    ----------
    rows
        One row per baseline policy: ``policy``, ``episodes``, and per main-table metric
        ``<metric>`` (the run's "mean ± std" at the paper's decimals), ``<metric>_paper`` and
        ``<metric>_equal``.
    equal_cells, cells
        How many printed cells equal the paper's, of how many compared.
    """

    rows: pd.DataFrame
    equal_cells: int
    cells: int

    @property
    def all_equal(self) -> bool:
        return self.cells > 0 and self.equal_cells == self.cells


def main_table_against_paper(metrics: pd.DataFrame) -> BaselineComparison:
    """The baselines' rows of the main table (mean ± sample std over the rollouts) beside the paper's.

    ``metrics`` holds ``metrics.csv`` rows; only the main setting is read when a ``setting``
    column is present. Policies other than the paper's rule baselines are left out.
    """
    if "setting" in metrics.columns:
        metrics = metrics[metrics["setting"] == SETTING_MAIN]
    means = table_values("tab:main-performance", "mean")
    rows, equal, cells = [], 0, 0
    for policy in [p for p in HEURISTICS if p in set(metrics["policy"])]:
        group = metrics[metrics["policy"] == policy]
        row = {"policy": policy, "episodes": len(group)}
        for paper in means[means["policy"] == policy].to_dict("records"):
            mean, std = mean_std(group[paper["metric"]])
            ours = pm(mean, std, paper["decimals"])
            published = f"{paper['printed']} ± {paper_value(paper['id'].removesuffix(':mean') + ':std')['printed']}"
            row |= {
                paper["metric"]: ours,
                f"{paper['metric']}_paper": published,
                f"{paper['metric']}_equal": ours == published,
            }
            equal, cells = equal + (ours == published), cells + 1
        rows.append(row)
    return BaselineComparison(pd.DataFrame(rows), equal, cells)


__all__ = [
    "AGAINST_KEYS",
    "BaselineComparison",
    "against_paper_tables",
    "main_table_against_paper",
    "AGAINST_CHOICES",
    "Check",
    "against_verdict",
    "check_tables",
    "checks_table",
]
