"""Training seeds: how much the learned rows depend on which seeds were trained.

The paper trains each algorithm with three seeds; in a paper root a learned policy's run seed
is its training seed. Per algorithm and metric the report puts the **between-seed** spread (the
sample standard deviation of the per-seed means) beside the **between-episode** spread (the
pooled within-seed standard deviation), and beside the spread a seed mean would have from
episode noise alone (between-episode SD / √episodes per seed). A between-seed SD well above
that says the training seed, not the evaluation episodes, moves the row.

The **seed bootstrap** redraws each learned policy's training seeds with replacement
(independently per policy, the same draw in every setting, so paired rows stay paired; the
rule baselines are not trained and keep all their rollouts) and recomputes every estimate.
The share of resamples in which the paper's ranking or finding still holds is reported; with
three seeds there are only ten distinct resamples per policy, so a share between 5 % and 95 %
is reported as "3 seeds cannot decide".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ...evaluation.settings import SETTING_MAIN
from ...tasks.registry import DEFAULT_TASK, get_task
from ..loading import ReportData
from ..naming import paper_order, policy_label
from ..options import ReportOptions
from ..paper.tables.performance import MAIN_METRICS
from ..table_model import Column, ReportTable, Skipped, cell, fixed, integer, text
from .paper_estimates import RunEstimates
from .paper_findings import better_sign, compared_refs, finding_condition
from .paper_reference import Finding, Ref, metric_better, table_values

#: A share of seed resamples at or above this (or at or below 1 - this) decides a finding.
DECIDED_SHARE = 0.95


@dataclass(frozen=True)
class SeedDraws:
    """B redraws of each learned policy's training seeds.

    Attributes
    ----------
    seeds
        Policy -> its training seeds (sorted).
    counts
        Policy -> (B, k) array: how often each of its k seeds is drawn in each resample.
    """

    seeds: dict[str, np.ndarray]
    counts: dict[str, np.ndarray]
    n_resamples: int

    def weights(self, rows: pd.DataFrame) -> np.ndarray:
        """(B, len(rows)) row weights: a learned policy's rollout counts as often as its seed was drawn."""
        weights = np.ones((self.n_resamples, len(rows)))
        policies = rows["policy"].to_numpy()
        run_seeds = rows["run_seed"].to_numpy()
        for policy, seeds in self.seeds.items():
            mask = policies == policy
            if mask.any():
                weights[:, mask] = self.counts[policy][:, np.searchsorted(seeds, run_seeds[mask])]
        return weights

    def n_seeds(self, policies) -> int:
        """The fewest training seeds among ``policies`` that are learned (0 when none is)."""
        counts = [len(self.seeds[p]) for p in policies if p in self.seeds]
        return min(counts) if counts else 0


def draw_seeds(metrics: pd.DataFrame, *, n_resamples: int, seed: int) -> SeedDraws:
    """Draw ``n_resamples`` resamples of every learned policy's run seeds (policies in name order)."""
    rng = np.random.default_rng(seed)
    seeds, counts = {}, {}
    for policy in sorted(set(metrics["policy"]) - set(get_task(DEFAULT_TASK).baselines())):
        own = np.array(sorted(set(metrics.loc[metrics["policy"] == policy, "run_seed"])))
        seeds[policy] = own
        counts[policy] = rng.multinomial(len(own), np.full(len(own), 1.0 / len(own)), size=n_resamples).astype(float)
    return SeedDraws(seeds, counts, n_resamples)


def seed_decision(share: float, n_seeds: int) -> str:
    """What the seed bootstrap says: "decided: holds", "decided: flips" or "N seeds cannot decide"."""
    if n_seeds < 2 or np.isnan(share):
        return f"{n_seeds} seed{'s' if n_seeds != 1 else ''} cannot decide (no spread to resample)"
    if share >= DECIDED_SHARE:
        return "decided: holds"
    if share <= 1.0 - DECIDED_SHARE:
        return "decided: flips"
    return f"{n_seeds} seeds cannot decide"


def _share(conditions: np.ndarray, values: list[np.ndarray]) -> float:
    """The share of resamples where the condition holds, among those where every value is defined."""
    valid = np.logical_and.reduce([np.isfinite(v) for v in values])
    return float(conditions[valid].mean()) if valid.any() else float("nan")


def finding_seed_share(finding: Finding, estimates: RunEstimates, draws: SeedDraws) -> float | None:
    """The share of seed resamples in which ``finding`` holds; None when the run lacks a quantity."""
    found = {ref: estimates.get(ref) for ref in compared_refs(finding)}
    if any(e is None for e in found.values()):
        return None
    values = {ref: e.replicates(draws.weights(e.rows)) for ref, e in found.items() if e is not None}
    return _share(finding_condition(finding, values), list(values.values()))


def ranking_seed_share(order: dict[str, float], refs: dict[str, Ref], estimates: RunEstimates, draws: SeedDraws):
    """The share of seed resamples that keep every strict pairwise order of ``order``.

    Parameters
    ----------
    order
        Policy -> the paper's value; pairs the paper prints as equal are not compared.
    refs
        Policy -> the run quantity to compare.

    Returns
    -------
    (share, run_values)
        The share (NaN when a policy is missing from the run) and the run's value per policy.
    """
    found = {p: estimates.get(ref) for p, ref in refs.items()}
    if any(e is None for e in found.values()):
        return float("nan"), {}
    values = {p: e.replicates(draws.weights(e.rows)) for p, e in found.items() if e is not None}
    pairs = [(a, b) for a in order for b in order if order[a] > order[b]]
    with np.errstate(invalid="ignore"):
        conditions = np.logical_and.reduce([values[a] > values[b] for a, b in pairs]) if pairs else np.ones(1, bool)
    run_values = {p: e.value for p, e in found.items() if e is not None}
    return _share(np.atleast_1d(conditions), list(values.values())), run_values


def seed_spread(metrics: pd.DataFrame, setting: str, columns: list[str]) -> pd.DataFrame:
    """Per learned policy and metric of ``setting``: the between-seed and between-episode spread.

    Columns: ``policy``, ``metric``, ``seeds``, ``episodes_per_seed`` (the mean), ``seed_means``
    (per seed, in seed order), ``between_seed_sd`` (ddof=1 over the seed means; NaN for one seed),
    ``between_episode_sd`` (pooled within-seed SD), ``episode_noise_sd`` (between-episode SD /
    √episodes per seed: the between-seed SD episode noise alone would give) and ``ratio``
    (between-seed SD / episode noise SD).
    """
    rows = []
    in_setting = metrics[metrics["setting"] == setting]
    for policy in sorted(set(in_setting["policy"]) - set(get_task(DEFAULT_TASK).baselines())):
        group = in_setting[in_setting["policy"] == policy]
        for column in columns:
            by_seed = group.groupby("run_seed")[column]
            means, sizes, variances = by_seed.mean(), by_seed.size(), by_seed.var(ddof=1).fillna(0.0)
            dof = float((sizes - 1).sum())
            episode_sd = float(np.sqrt(((sizes - 1) * variances).sum() / dof)) if dof > 0 else float("nan")
            between = float(means.std(ddof=1)) if len(means) > 1 else float("nan")
            noise = episode_sd / float(np.sqrt(sizes.mean()))
            rows.append(
                {
                    "policy": policy,
                    "metric": column,
                    "seeds": int(len(means)),
                    "episodes_per_seed": float(sizes.mean()),
                    "seed_means": [float(m) for m in means],
                    "between_seed_sd": between,
                    "between_episode_sd": episode_sd,
                    "episode_noise_sd": noise,
                    "ratio": between / noise if noise > 0 else float("nan"),
                }
            )
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- tables

NOT_PAPER_ROOT = (
    "not a paper root: a run directory evaluates one model per learned policy, so its run seeds are not training seeds"
)


def _digits(metric: str) -> int:
    return next(d for name, _, d in MAIN_METRICS if name == metric)


def _header(metric: str) -> str:
    return next(h for name, h, _ in MAIN_METRICS if name == metric)


def seed_spread_table(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Per learned policy and main-table metric: between-seed beside between-episode spread."""
    title = "Training-seed spread of the learned policies"
    if data.kind != "paper":
        return Skipped("seed_spread", title, NOT_PAPER_ROOT)
    frame = seed_spread(data.metrics, SETTING_MAIN, [m for m, _, _ in MAIN_METRICS])
    if frame.empty:
        return Skipped("seed_spread", title, "no learned policy in the main setting")
    frame["policy"] = frame["policy"].map(policy_label)

    def digits(name: str):
        return lambda r: fixed(r[name], _digits(r["metric"]) + 1)

    columns = [
        Column("Policy", text("policy"), align="l"),
        Column("Metric", lambda r: _header(r["metric"]), align="l"),
        Column("Seeds", integer("seeds")),
        Column("Seed means", lambda r: ", ".join(fixed(m, _digits(r["metric"])) for m in r["seed_means"])),
        Column("Between-seed SD", digits("between_seed_sd")),
        Column("Between-episode SD", digits("between_episode_sd")),
        Column("Episode noise SD", digits("episode_noise_sd")),
        Column("Ratio", cell("ratio", 1)),
    ]
    return ReportTable(
        key="seed_spread",
        label="tab:seed-spread",
        title=title,
        caption=(
            "Main setting. Between-seed SD: sample SD of the per-training-seed means; between-episode SD: pooled "
            "within-seed SD of the rollouts; episode noise SD: between-episode SD / sqrt(episodes per seed), what "
            "episode noise alone would give the seed means; ratio: between-seed SD / episode noise SD (well above "
            "1: the training seed moves the row)."
        ),
        columns=columns,
        data=frame,
        basis=f"Seeds per policy: {', '.join(str(n) for n in sorted(set(frame['seeds'])))}.",
    )


def _ranking(values: dict[str, float], metric: str) -> str:
    sign = better_sign(metric)
    ordered = sorted(values, key=lambda p: -sign * values[p])
    return " > ".join(policy_label(p) for p in ordered)


def seed_ranking_table(
    data: ReportData, options: ReportOptions, draws: SeedDraws | None, estimates: RunEstimates | None = None
) -> ReportTable | Skipped:
    """Per main-table metric: the paper's ranking of the policies and the share of seed resamples keeping it
    (``draws``: the training-seed resamples; None outside a paper root)."""
    title = "The paper's rankings under resampled training seeds"
    if data.kind != "paper" or draws is None:
        return Skipped("seed_rankings", title, NOT_PAPER_ROOT)
    means = table_values("tab:main-performance", "mean")
    estimates, rows = estimates or RunEstimates(data.metrics), []
    for metric in metric_better():
        paper = {r["policy"]: r["value"] for r in means[means["metric"] == metric].to_dict("records")}
        refs = {p: Ref(SETTING_MAIN, None, p, metric, "mean") for p in paper_order(paper)}
        share, run = ranking_seed_share(paper, refs, estimates, draws)
        rows.append(
            {
                "metric": metric,
                "paper_ranking": _ranking(paper, metric),
                "run_ranking": _ranking(run, metric) if run else "not in run",
                "seed_share": share,
                "seeds": seed_decision(share, draws.n_seeds(paper)) if run else "–",
            }
        )
    columns = [
        Column("Metric", lambda r: _header(r["metric"]), align="l"),
        Column("Paper ranking (best first)", text("paper_ranking"), align="l"),
        Column("Run ranking", text("run_ranking"), align="l"),
        Column(
            "Seed resamples keeping it",
            lambda r: "–" if np.isnan(r["seed_share"]) else f"{100 * r['seed_share']:.0f} %",
        ),
        Column("Seeds", text("seeds"), align="l"),
    ]
    return ReportTable(
        key="seed_rankings",
        label="tab:seed-rankings",
        title=title,
        caption=(
            "Main setting. The share of resamples of the learned policies' training seeds in which every pairwise "
            "order of the paper's main table holds (pairs the paper prints as equal are not compared; the rule "
            "baselines keep all their rollouts)."
        ),
        columns=columns,
        data=pd.DataFrame(rows),
        basis=f"Seed resamples: {draws.n_resamples}, seed {options.seed}.",
    )


__all__ = [
    "DECIDED_SHARE",
    "NOT_PAPER_ROOT",
    "seed_ranking_table",
    "seed_spread_table",
    "SeedDraws",
    "draw_seeds",
    "finding_seed_share",
    "ranking_seed_share",
    "seed_decision",
    "seed_spread",
]
