"""Statistics for the report: the paper's (mean ± sample std, Welch's t-test, paired deltas) and
the honest ones beyond it (cluster-bootstrap CIs, interquartile mean, probability of improvement).

Why clusters. The paper protocol resets episode ``e`` of run seed ``s`` with seed ``s + e``, so
the three run seeds × 30 episodes of a policy share most episode seeds (32 distinct seeds, 21
distinct start days among 90 rollouts). Rollouts that start on the same day see the same
weather, demand and price path and are not independent. The bootstrap here therefore resamples
whole clusters (start days by default; any label per row works), the rliable methodology's
stratified bootstrap applied to the actual independent unit. Every resampling is seeded, so the
output is deterministic.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from ..tasks.base import DEFAULT_STEPS_PER_DAY
from .options import DEFAULT_CONFIDENCE as DEFAULT_CONFIDENCE
from .options import DEFAULT_RESAMPLES as DEFAULT_RESAMPLES
from .options import DEFAULT_SEED as DEFAULT_SEED

ArrayLike = Sequence[float] | np.ndarray | pd.Series


@dataclass(frozen=True)
class Interval:
    """A point estimate with a two-sided confidence interval (``nan`` bounds when undefined)."""

    estimate: float
    low: float
    high: float


@dataclass(frozen=True)
class WelchTest:
    """Welch's unequal-variance t-test of mean(a) - mean(b)."""

    mean_a: float
    mean_b: float
    n_a: int
    n_b: int
    t_statistic: float
    dof: float
    p_value: float


@dataclass(frozen=True)
class SampleSize:
    """How many rows a statistic rests on and how many independent episodes lie behind them."""

    n: int
    episode_seeds: int
    start_days: int


def _array(values: ArrayLike) -> np.ndarray:
    return np.asarray(values, dtype=float)


def mean_std(values: ArrayLike) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof=1, as in the paper); std is ``nan`` for n < 2."""
    x = _array(values)
    if x.size == 0:
        return float("nan"), float("nan")
    return float(x.mean()), float(x.std(ddof=1)) if x.size > 1 else float("nan")


def t_interval(values: ArrayLike, confidence: float = DEFAULT_CONFIDENCE) -> Interval:
    """Student-t confidence interval of the mean (e.g. across run seeds); ``nan`` bounds for n < 2."""
    x = _array(values)
    mean = float(x.mean()) if x.size else float("nan")
    if x.size < 2:
        return Interval(mean, float("nan"), float("nan"))
    half = float(stats.t.ppf(0.5 + confidence / 2, x.size - 1) * x.std(ddof=1) / np.sqrt(x.size))
    return Interval(mean, mean - half, mean + half)


def welch_test(a: ArrayLike, b: ArrayLike) -> WelchTest:
    """Welch's two-sided t-test that mean(a) == mean(b), every row taken as independent (as the paper)."""
    x, y = _array(a), _array(b)
    result = stats.ttest_ind(x, y, equal_var=False)
    return WelchTest(
        mean_a=float(x.mean()),
        mean_b=float(y.mean()),
        n_a=int(x.size),
        n_b=int(y.size),
        t_statistic=float(result.statistic),
        dof=float(result.df),
        p_value=float(result.pvalue),
    )


def cluster_means(values: ArrayLike, clusters: ArrayLike) -> pd.Series:
    """Mean of ``values`` per cluster label, indexed by label (sorted)."""
    return pd.Series(_array(values)).groupby(np.asarray(clusters)).mean()


def paired_cluster_test(a: ArrayLike, a_clusters: ArrayLike, b: ArrayLike, b_clusters: ArrayLike) -> tuple[float, int]:
    """Paired t-test on per-cluster means over the clusters both samples share.

    Returns
    -------
    (p_value, n_clusters)
        Two-sided p-value (``nan`` with fewer than 2 shared clusters) and the clusters used.
    """
    mean_a, mean_b = cluster_means(a, a_clusters), cluster_means(b, b_clusters)
    shared = mean_a.index.intersection(mean_b.index)
    if len(shared) < 2:
        return float("nan"), int(len(shared))
    return float(stats.ttest_rel(mean_a[shared], mean_b[shared]).pvalue), int(len(shared))


def sample_size(frame: pd.DataFrame) -> SampleSize:
    """Rows, distinct episode seeds and distinct start hours (days) of ``frame``."""
    return SampleSize(
        n=int(len(frame)),
        episode_seeds=int(frame["episode_seed"].nunique()) if "episode_seed" in frame else 0,
        start_days=int(frame["start_hour"].nunique()) if "start_hour" in frame else 0,
    )


def start_days(start_hours: ArrayLike, steps_per_day: int = DEFAULT_STEPS_PER_DAY) -> np.ndarray:
    """Each episode's start day, ``start_hour // steps_per_day`` (int64): the cluster the bootstrap
    resamples. ``start_hour`` is the episode's first step; ``steps_per_day`` is the task's
    (:func:`~solarchain_eval.tasks.base.steps_per_day_of`: 24 for the solar market's hours, 1 for
    the supply-chain market, whose steps are days)."""
    return (pd.to_numeric(pd.Series(np.asarray(start_hours))).to_numpy() // int(steps_per_day)).astype(np.int64)


@dataclass
class PairedDeltas:
    """Per-rollout differences ``treated - base`` of matched rollouts.

    ``frame`` has policy, run_seed, episode, episode_seed, start_hour and one column per metric
    holding the delta; ``unmatched`` counts rollouts of either setting without a partner.
    """

    frame: pd.DataFrame
    unmatched: int


def paired_deltas(
    metrics: pd.DataFrame, base_setting: str, treated_setting: str, columns: Sequence[str]
) -> PairedDeltas:
    """Differences treated - base matched on setting pair, policy, run seed and episode.

    Raises
    ------
    ValueError
        A matched pair was reset with different episode seeds (the two runs used different protocols).
    """
    key = ["policy", "run_seed", "episode"]
    keep = [*key, "episode_seed", "start_hour", *columns]
    base = metrics.loc[metrics["setting"] == base_setting, keep]
    treated = metrics.loc[metrics["setting"] == treated_setting, keep]
    merged = base.merge(treated, on=key, how="inner", suffixes=("_base", "_treated"), validate="one_to_one")
    mismatch = merged["episode_seed_base"] != merged["episode_seed_treated"]
    if mismatch.any():
        row = merged[mismatch].iloc[0]
        raise ValueError(
            f"rollout policy={row['policy']} run_seed={row['run_seed']} episode={row['episode']} was reset with "
            f"episode seed {row['episode_seed_base']} in {base_setting} but {row['episode_seed_treated']} in "
            f"{treated_setting}; paired deltas need the same protocol"
        )
    frame = merged[key].copy()
    frame["episode_seed"] = merged["episode_seed_base"].to_numpy()
    frame["start_hour"] = merged["start_hour_base"].to_numpy()
    for column in columns:
        frame[column] = merged[f"{column}_treated"].to_numpy() - merged[f"{column}_base"].to_numpy()
    frame = frame.sort_values(key, kind="stable").reset_index(drop=True)
    return PairedDeltas(frame=frame, unmatched=int(len(base) + len(treated) - 2 * len(frame)))


def interquartile_mean(values: ArrayLike, weights: np.ndarray | None = None) -> np.ndarray | float:
    """Mean of the middle 50 % of the (weighted) distribution of ``values`` (rliable's IQM).

    Each value carries mass ``weight``; the IQM averages the mass between the 25 % and 75 %
    points, splitting a value that straddles a boundary. With unit weights and n a multiple of
    4 this equals ``scipy.stats.trim_mean(values, 0.25)``.

    Parameters
    ----------
    values
        n values.
    weights
        ``None`` (unit weights), shape (n,), or shape (B, n) for B weightings at once.

    Returns
    -------
    float, or an array of B IQMs when ``weights`` is 2-D.
    """
    x = _array(values)
    order = np.argsort(x, kind="stable")
    w = np.ones_like(x) if weights is None else np.asarray(weights, dtype=float)
    w2 = np.atleast_2d(w)[:, order]
    upper_edge = np.cumsum(w2, axis=1)
    total = upper_edge[:, -1:]
    overlap = np.clip(np.minimum(upper_edge, 0.75 * total) - np.maximum(upper_edge - w2, 0.25 * total), 0.0, None)
    iqm = (overlap * x[order]).sum(axis=1) / (0.5 * total[:, 0])
    return float(iqm[0]) if np.ndim(w) == 1 else iqm


def probability_of_improvement(
    x: ArrayLike, y: ArrayLike, wx: np.ndarray | None = None, wy: np.ndarray | None = None
) -> np.ndarray | float:
    """P(X > Y) + 0.5 P(X = Y) over all (weighted) pairs: rliable's probability of improvement.

    This is the Mann-Whitney U statistic divided by n_x n_y. ``wx``/``wy`` weight the rows
    (1-D, or 2-D (B, n) for B weightings at once).
    """
    a, b = _array(x), _array(y)
    score = (a[:, None] > b[None, :]).astype(float) + 0.5 * (a[:, None] == b[None, :])
    if wx is None and wy is None:
        return float(score.mean())
    w_a = np.atleast_2d(np.ones_like(a) if wx is None else wx)
    w_b = np.atleast_2d(np.ones_like(b) if wy is None else wy)
    value = ((w_a @ score) * w_b).sum(axis=1) / (w_a.sum(axis=1) * w_b.sum(axis=1))
    return float(value[0]) if value.size == 1 and np.ndim(wx) <= 1 and np.ndim(wy) <= 1 else value


def cluster_bootstrap(
    statistic: Callable[[np.ndarray], np.ndarray],
    clusters: ArrayLike,
    *,
    n_resamples: int = DEFAULT_RESAMPLES,
    confidence: float = DEFAULT_CONFIDENCE,
    seed: int = DEFAULT_SEED,
) -> Interval:
    """Percentile bootstrap interval of a statistic, resampling whole clusters with replacement.

    Parameters
    ----------
    statistic
        Maps row weights of shape (B, n) to B estimates; a resample gives each row the number
        of times its cluster was drawn, so the full sample is all-ones weights.
    clusters
        n cluster labels, one per row (e.g. start hours).
    n_resamples, confidence, seed
        Bootstrap resamples, two-sided confidence level, seed of the resampling stream.

    Returns
    -------
    Interval
        The full-sample estimate and the percentile interval (``nan`` bounds with < 2 clusters).
    """
    codes, labels = pd.factorize(pd.Series(np.asarray(clusters)), sort=True)
    n_clusters = len(labels)
    estimate = float(np.asarray(statistic(np.ones((1, codes.size))))[0])
    if n_clusters < 2:
        return Interval(estimate, float("nan"), float("nan"))

    def resampled(indices: np.ndarray, axis: int = -1) -> np.ndarray:
        drawn = np.asarray(indices, dtype=np.intp)
        flat = drawn.reshape(-1, drawn.shape[-1])
        counts = np.zeros((flat.shape[0], n_clusters))
        np.add.at(counts, (np.repeat(np.arange(flat.shape[0]), flat.shape[1]), flat.ravel()), 1.0)
        return np.asarray(statistic(counts[:, codes])).reshape(drawn.shape[:-1])

    result = stats.bootstrap(
        (np.arange(n_clusters),),
        resampled,
        n_resamples=n_resamples,
        confidence_level=confidence,
        method="percentile",
        vectorized=True,
        rng=np.random.default_rng(seed),
    )
    return Interval(estimate, float(result.confidence_interval.low), float(result.confidence_interval.high))


def bootstrap_mean(values: ArrayLike, clusters: ArrayLike, **options) -> Interval:
    """Mean with a cluster-bootstrap interval (``options``: n_resamples, confidence, seed)."""
    x = _array(values)
    return cluster_bootstrap(lambda w: (w @ x) / w.sum(axis=1), clusters, **options)


def bootstrap_iqm(values: ArrayLike, clusters: ArrayLike, **options) -> Interval:
    """Interquartile mean with a cluster-bootstrap interval."""
    x = _array(values)
    return cluster_bootstrap(lambda w: interquartile_mean(x, w), clusters, **options)


def _joint(a: ArrayLike, a_clusters: ArrayLike, b: ArrayLike, b_clusters: ArrayLike):
    x, y = _array(a), _array(b)
    labels = np.concatenate([np.asarray(a_clusters), np.asarray(b_clusters)])
    return x, y, labels


def bootstrap_mean_difference(
    a: ArrayLike, a_clusters: ArrayLike, b: ArrayLike, b_clusters: ArrayLike, **options
) -> Interval:
    """mean(a) - mean(b) with an interval that resamples the clusters of both samples jointly.

    Clusters shared by ``a`` and ``b`` (the same start day) are drawn together, keeping the
    pairing of policies evaluated on the same days.
    """
    x, y, labels = _joint(a, a_clusters, b, b_clusters)

    def difference(w: np.ndarray) -> np.ndarray:
        wa, wb = w[:, : x.size], w[:, x.size :]
        return (wa @ x) / wa.sum(axis=1) - (wb @ y) / wb.sum(axis=1)

    return cluster_bootstrap(difference, labels, **options)


def bootstrap_probability_of_improvement(
    a: ArrayLike, a_clusters: ArrayLike, b: ArrayLike, b_clusters: ArrayLike, **options
) -> Interval:
    """P(a > b) (probability of improvement) with a joint cluster-bootstrap interval."""
    x, y, labels = _joint(a, a_clusters, b, b_clusters)
    return cluster_bootstrap(
        lambda w: probability_of_improvement(x, y, w[:, : x.size], w[:, x.size :]), labels, **options
    )
