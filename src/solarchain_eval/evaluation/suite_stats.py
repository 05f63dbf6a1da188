"""Aggregate statistics of a suite's normalised scores, as rliable defines them (docs/suites.md).

An agent's scores form a matrix of shape ``(runs, tasks)``: one column per suite entry, one row
per episode (run seed × episode, in the same order on every entry). The functions below are
those of rliable (Agarwal et al., *Deep RL at the Edge of the Statistical Precipice*, NeurIPS
2021; ``rliable.metrics`` and ``rliable.library``), written out here so that rliable is not a
dependency:

- :func:`aggregate_iqm`: the interquartile mean of every score of the matrix (a 25 % trimmed mean,
  ``scipy.stats.trim_mean``);
- :func:`aggregate_mean` and :func:`aggregate_median`: the mean and the median of the per-task means;
- :func:`aggregate_optimality_gap`: how far the scores fall short of ``gamma`` (scores above it count
  as ``gamma``);
- :func:`probability_of_improvement`: P(X > Y) per task (the Mann-Whitney U statistic over
  ``runs_x × runs_y``), averaged over tasks;
- :func:`score_distribution`: the performance profile, the fraction of all scores above each threshold;
- :func:`stratified_bootstrap_interval`: a percentile interval from resampling the runs of each task
  independently (rliable's ``StratifiedBootstrap`` without task resampling).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import scipy.stats

from ..common.atomic_files import atomic_write_with

#: The aggregates a suite reports, in order (a larger value is better, except the optimality gap).
AGGREGATE_NAMES = ("iqm", "mean", "median", "optimality_gap")
#: Bootstrap resamples and the seed the suite's intervals use by default.
BOOTSTRAP_REPS = 2000
BOOTSTRAP_SEED = 0


def aggregate_iqm(scores: np.ndarray) -> float:
    """Interquartile mean of every score of the matrix: the middle half of the sorted scores, averaged."""
    return float(scipy.stats.trim_mean(np.asarray(scores, dtype=float), proportiontocut=0.25, axis=None))


def aggregate_mean(scores: np.ndarray) -> float:
    """Mean of the per-task mean scores."""
    return float(np.mean(np.mean(np.asarray(scores, dtype=float), axis=0)))


def aggregate_median(scores: np.ndarray) -> float:
    """Median of the per-task mean scores."""
    return float(np.median(np.mean(np.asarray(scores, dtype=float), axis=0)))


def aggregate_optimality_gap(scores: np.ndarray, gamma: float = 1.0) -> float:
    """``gamma`` minus the mean of the scores clipped from above at ``gamma`` (lower is better)."""
    return float(gamma - np.mean(np.minimum(np.asarray(scores, dtype=float), gamma)))


AGGREGATES: dict[str, Callable[[np.ndarray], float]] = {
    "iqm": aggregate_iqm,
    "mean": aggregate_mean,
    "median": aggregate_median,
    "optimality_gap": aggregate_optimality_gap,
}


def probability_of_improvement(scores_x: np.ndarray, scores_y: np.ndarray) -> float:
    """P(X > Y): per task, the share of (x run, y run) pairs where x scores more (ties count half),
    averaged over tasks. Both matrices have one column per task; their numbers of runs may differ."""
    x, y = np.asarray(scores_x, dtype=float), np.asarray(scores_y, dtype=float)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"the score matrices cover {x.shape[1]} and {y.shape[1]} tasks")
    per_task = []
    for task in range(x.shape[1]):
        if np.array_equal(x[:, task], y[:, task]):
            per_task.append(0.5)
            continue
        statistic = scipy.stats.mannwhitneyu(x[:, task], y[:, task], alternative="greater").statistic
        per_task.append(statistic / (x.shape[0] * y.shape[0]))
    return float(np.mean(per_task))


def score_distribution(scores: np.ndarray, taus: Sequence[float] | np.ndarray) -> np.ndarray:
    """The performance profile: for each threshold, the fraction of all scores strictly above it."""
    flat = np.asarray(scores, dtype=float).reshape(1, -1)
    return np.mean(flat > np.asarray(taus, dtype=float).reshape(-1, 1), axis=1)


def stratified_bootstrap_interval(
    scores: np.ndarray,
    statistic: Callable[[np.ndarray], float],
    *,
    reps: int = BOOTSTRAP_REPS,
    size: float = 0.95,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """A ``size`` percentile interval of ``statistic``: each resample draws, for every task (column)
    separately, as many runs as it has, with replacement; the same ``seed`` gives the same interval."""
    matrix = np.asarray(scores, dtype=float)
    runs, tasks = matrix.shape
    rng = np.random.default_rng(seed)
    columns = np.arange(tasks)
    estimates = np.empty(reps)
    for rep in range(reps):
        rows = rng.integers(0, runs, size=(runs, tasks))
        estimates[rep] = statistic(matrix[rows, columns])
    tail = 100 * (1 - size) / 2
    low, high = np.percentile(estimates, [tail, 100 - tail])
    return float(low), float(high)


def aggregate_table(
    matrices: Mapping[str, np.ndarray], *, reps: int = BOOTSTRAP_REPS, seed: int = BOOTSTRAP_SEED
) -> list[dict[str, float | str]]:
    """One row per agent: each aggregate of :data:`AGGREGATE_NAMES` with its 95 % interval
    (``<name>``, ``<name>_low``, ``<name>_high``)."""
    rows: list[dict[str, float | str]] = []
    for agent, matrix in matrices.items():
        row: dict[str, float | str] = {"policy": agent}
        for name in AGGREGATE_NAMES:
            function = AGGREGATES[name]
            row[name] = function(matrix)
            row[f"{name}_low"], row[f"{name}_high"] = stratified_bootstrap_interval(
                matrix, function, reps=reps, seed=seed
            )
        rows.append(row)
    return rows


def improvement_table(matrices: Mapping[str, np.ndarray]) -> list[dict[str, float | str]]:
    """P(X > Y) for every ordered pair of different agents."""
    return [
        {"policy": x, "over": y, "probability": probability_of_improvement(matrices[x], matrices[y])}
        for x in matrices
        for y in matrices
        if x != y
    ]


def profile_thresholds(matrices: Mapping[str, np.ndarray], points: int = 101) -> np.ndarray:
    """Thresholds spanning every score of every agent (the performance profile's x axis)."""
    values = np.concatenate([np.asarray(m, dtype=float).ravel() for m in matrices.values()])
    return np.linspace(float(values.min()), float(values.max()), points)


def draw_performance_profile(
    axes, matrices: Mapping[str, np.ndarray], colours: Mapping[str, str] | None = None
) -> None:
    """Draw every agent's performance profile (:func:`score_distribution`) on matplotlib ``axes``, with
    dotted lines at the reference levels 0 and 1 (the suite root's figure, the report's and the board's)."""
    taus = profile_thresholds(matrices)
    for agent, matrix in matrices.items():
        colour = {"color": colours[agent]} if colours and agent in colours else {}
        axes.plot(taus, score_distribution(matrix, taus), label=agent, **colour)
    for reference in (0.0, 1.0):
        axes.axvline(reference, color="grey", linewidth=0.8, linestyle=":")
    axes.set_xlabel("normalised score τ (0 and 1: the reference baselines)")
    axes.set_ylabel("fraction of episodes with score > τ")
    axes.set_ylim(-0.02, 1.02)
    axes.legend()


def performance_profile_figure(matrices: Mapping[str, np.ndarray], path: Path, title: str) -> Path:
    """Write the performance profile of every agent (:func:`score_distribution`) to ``path`` (PNG)."""
    from matplotlib.figure import Figure  # the object API: no pyplot state, no backend switch

    figure = Figure(figsize=(6, 4))
    axes = figure.subplots()
    draw_performance_profile(axes, matrices)
    axes.set_title(title)
    figure.tight_layout()
    atomic_write_with(path, lambda target: figure.savefig(target, format="png", dpi=120, metadata={"Software": None}))
    return path
