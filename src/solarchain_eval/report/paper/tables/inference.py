"""Inference tables: the paper's Welch tests, and cluster-bootstrap summaries beyond the paper."""

from __future__ import annotations

import pandas as pd

from ...loading import ReportData
from ...naming import is_learned, is_trained, paper_order, policy_label, setting_label
from ...options import ReportOptions
from ...statistics import (
    SampleSize,
    bootstrap_iqm,
    bootstrap_mean,
    bootstrap_mean_difference,
    bootstrap_probability_of_improvement,
    paired_cluster_test,
    welch_test,
)
from ...table_model import Column, ReportTable, Skipped, basis_sentence, fixed, integer, p_value, text, with_interval
from .common import size_fields, sizes_of

UNIT_NAMES = {"start_hour": "start days", "episode_seed": "episode seeds"}
SUMMARY_METRICS = (
    ("physics_violation_rate", "Violation", 4),
    ("artificial_liquidity_MWh", "Artificial Liquidity", 4),
    ("mean_slippage", "Slippage", 4),
)


def _comparisons(rollouts: pd.DataFrame) -> list[tuple[str, pd.DataFrame, pd.DataFrame]]:
    """The paper's comparisons: RL vs non-RL pooled and each learner vs each baseline (user
    agents are compared with each baseline too, but not pooled into "RL").

    Without learned policies (or without baselines), every pair of policies present.
    """
    policies = paper_order(rollouts["policy"])
    rows = {p: rollouts[rollouts["policy"] == p] for p in policies}
    learned = [p for p in policies if is_learned(p)]
    baselines = [p for p in policies if not is_learned(p)]
    trained = [p for p in learned if is_trained(p)]
    if learned and baselines:
        pooled = [
            (
                "RL vs non-RL",
                rollouts[rollouts["policy"].isin(trained)],
                rollouts[rollouts["policy"].isin(baselines)],
            )
        ]
        return (pooled if trained else []) + [
            (f"{policy_label(a)} vs {policy_label(b)}", rows[a], rows[b]) for a in learned for b in baselines
        ]
    return [
        (f"{policy_label(a)} vs {policy_label(b)}", rows[a], rows[b])
        for i, b in enumerate(policies)
        for a in policies[i + 1 :]
    ]


def _comparison_row(
    setting: str, label: str, a: pd.DataFrame, b: pd.DataFrame, unit: str, options: ReportOptions
) -> dict:
    """One comparison's figures: Welch test, paired cluster test, bootstrap Δ mean and P(A > B)."""
    x, y = a["cumulative_reward"].to_numpy(float), b["cumulative_reward"].to_numpy(float)
    welch = welch_test(x, y)
    paired_p, shared = paired_cluster_test(x, a[unit], y, b[unit])
    diff = bootstrap_mean_difference(x, a[unit], y, b[unit], **options.bootstrap())
    poi = bootstrap_probability_of_improvement(x, a[unit], y, b[unit], **options.bootstrap())
    return {
        "setting": setting_label(setting),
        "comparison": label,
        **size_fields(pd.concat([a, b])),
        "n_a": welch.n_a,
        "n_b": welch.n_b,
        "mean_a": welch.mean_a,
        "mean_b": welch.mean_b,
        "difference": diff.estimate,
        "difference_low": diff.low,
        "difference_high": diff.high,
        "welch_t": welch.t_statistic,
        "welch_dof": welch.dof,
        "welch_p": welch.p_value,
        "paired_cluster_p": paired_p,
        "shared_clusters": shared,
        "probability_of_improvement": poi.estimate,
        "probability_of_improvement_low": poi.low,
        "probability_of_improvement_high": poi.high,
    }


def statistical_tests(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Cumulative-reward comparisons: Welch (as the paper), paired cluster test, bootstrap CI, P(A > B)."""
    title = "Statistical tests of cumulative reward"
    unit = options.cluster_by
    rows = [
        _comparison_row(setting, label, a, b, unit, options)
        for setting in data.settings
        for label, a, b in _comparisons(data.rollouts(setting))
    ]
    if not rows:
        return Skipped("statistical_tests", title, "no setting has two or more policies to compare")
    frame = pd.DataFrame(rows)
    unit_name = UNIT_NAMES[unit]
    columns = [
        Column("Setting", text("setting"), align="l"),
        Column("Comparison (A vs B)", text("comparison"), align="l"),
        Column("n (A / B)", lambda r: f"{int(r['n_a'])} / {int(r['n_b'])}"),
        Column("Mean A", lambda r: fixed(r["mean_a"], 2)),
        Column("Mean B", lambda r: fixed(r["mean_b"], 2)),
        Column(
            "Δ Mean [95% CI]",
            lambda r: with_interval(r["difference"], r["difference_low"], r["difference_high"], 2),
            latex=r"$\Delta$ Mean [95\% CI]",
        ),
        Column("Welch t", lambda r: fixed(r["welch_t"], 2)),
        Column("Welch p", lambda r: p_value(r["welch_p"])),
        Column(
            f"Paired p ({unit_name})", lambda r: f"{p_value(r['paired_cluster_p'])} (n={int(r['shared_clusters'])})"
        ),
        Column(
            "P(A > B) [95% CI]",
            lambda r: with_interval(
                r["probability_of_improvement"],
                r["probability_of_improvement_low"],
                r["probability_of_improvement_high"],
                3,
            ),
            latex=r"P(A $>$ B) [95\% CI]",
        ),
    ]
    level = f"{options.confidence:.0%}"
    return ReportTable(
        key="statistical_tests",
        label="tab:statistical-tests",
        title=title,
        caption=(
            "Cumulative-reward comparisons per setting. Welch's t-test reproduces the paper's test, which treats "
            "every rollout as an independent sample. Because rollouts share start days, the paired t-test instead "
            f"averages each side's rollouts per {unit_name[:-1]} and pairs the {unit_name} both sides share. Δ mean "
            f"and the probability of improvement P(A > B) + ½P(A = B) (rliable) carry {level} percentile intervals "
            f"from a cluster bootstrap that resamples whole {unit_name} ({options.n_resamples} resamples, seed "
            f"{options.seed})."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "rollouts (A and B together)"),
    )


def robust_summary(data: ReportData, options: ReportOptions) -> ReportTable | Skipped:
    """Per setting and policy: mean and IQM of reward, and mean risk metrics, with bootstrap CIs."""
    title = "Cluster-bootstrap summaries"
    unit = options.cluster_by
    rows = []
    for setting in data.settings:
        rollouts = data.rollouts(setting)
        for policy in paper_order(rollouts["policy"]):
            group = rollouts[rollouts["policy"] == policy]
            clusters = group[unit].to_numpy()
            reward = group["cumulative_reward"].to_numpy(float)
            row = {"setting": setting_label(setting), "policy": policy_label(policy), **size_fields(group)}
            for name, interval in (
                ("reward_mean", bootstrap_mean(reward, clusters, **options.bootstrap())),
                ("reward_iqm", bootstrap_iqm(reward, clusters, **options.bootstrap())),
            ):
                row |= {name: interval.estimate, f"{name}_low": interval.low, f"{name}_high": interval.high}
            for metric, _, _ in SUMMARY_METRICS:
                interval = bootstrap_mean(group[metric].to_numpy(float), clusters, **options.bootstrap())
                row |= {metric: interval.estimate, f"{metric}_low": interval.low, f"{metric}_high": interval.high}
            rows.append(row)
    frame = pd.DataFrame(rows)

    def ci(name: str, digits: int):
        return lambda r: with_interval(r[name], r[f"{name}_low"], r[f"{name}_high"], digits)

    columns = [
        Column("Setting", text("setting"), align="l"),
        Column("Policy", text("policy"), align="l"),
        Column("n", integer("n")),
        Column(
            f"{UNIT_NAMES[unit].capitalize()}",
            integer("distinct_start_days" if unit == "start_hour" else "distinct_episode_seeds"),
        ),
        Column("Reward Mean [95% CI]", ci("reward_mean", 2), latex=r"Reward Mean [95\% CI]"),
        Column("Reward IQM [95% CI]", ci("reward_iqm", 2), latex=r"Reward IQM [95\% CI]"),
    ]
    columns += [
        Column(f"{header} [95% CI]", ci(name, d), latex=f"{header} [95\\% CI]") for name, header, d in SUMMARY_METRICS
    ]
    return ReportTable(
        key="robust_summary",
        label="tab:robust-summary",
        title=title,
        caption=(
            "Means and the interquartile mean (IQM: mean of the middle 50 % of rollouts, rliable) with "
            f"{options.confidence:.0%} percentile intervals from a cluster bootstrap that resamples whole "
            f"{UNIT_NAMES[unit]} ({options.n_resamples} resamples, seed {options.seed}), so that rollouts sharing "
            "a start day count once as a unit rather than as independent samples."
        ),
        columns=columns,
        data=frame,
        basis=basis_sentence(sizes_of(frame), "rollouts"),
    )


def overlap_warning(metrics: pd.DataFrame, cluster_by: str = "start_hour") -> str | None:
    """A warning when rollouts of one policy and setting share episode seeds or start days."""
    worst: SampleSize | None = None
    for _, group in metrics.groupby(["setting", "policy"], sort=True):
        size = SampleSize(len(group), int(group["episode_seed"].nunique()), int(group["start_hour"].nunique()))
        if size.start_days < size.n and (worst is None or size.n / size.start_days > worst.n / worst.start_days):
            worst = size
    if worst is None:
        return None
    return (
        f"Rollouts overlap: a policy's {worst.n} rollouts come from only {worst.episode_seeds} distinct episode "
        f"seeds and {worst.start_days} distinct start days (the paper protocol resets episode e of run seed s "
        "with seed s + e, so consecutive run seeds share most episode seeds). Rollouts on the same day are not "
        "independent: the mean ± std tables and the paper's Welch tests treat them as if they were. The "
        "bootstrap intervals, the paired p-values and the probabilities of improvement here resample or pair "
        f"whole {UNIT_NAMES[cluster_by]}."
    )


__all__ = ["statistical_tests", "robust_summary", "overlap_warning"]
