"""The sensitivity report of a sweep: each metric against each axis, and where paper findings flip.

Both tables resample start days (an episode's ``start_hour // steps_per_day``: 24 hours for the
solar market, 1 for the supply-chain market's days; :func:`~solarchain_eval.tasks.base.steps_per_day_of`)
with the cluster bootstrap of :mod:`.statistics`: episodes that start on the same day share its
weather and attacks, so a day is the unit of independent evidence (docs/statistics.md).

- ``sensitivity.csv``: for every axis, axis value, setting, policy and metric, the mean over all
  episodes at that value (pooled over the other axes' values) with its 95 % interval.
- ``findings.csv``: for every point, the paper's findings re-tested on the point's episodes:

  * ``rl_over_heuristics`` (setting ``main``): the best learned policy's mean cumulative reward
    minus the best heuristic's (best = highest mean at that point);
  * ``artificial_liquidity_rise`` (per learned policy): its mean artificial liquidity in
    ``no_physics`` minus in ``main``;
  * ``cost_within_limit`` (``ppo-lag``, per setting): the cost limit D minus the mean episode cost.

  The paper's direction is "> 0" for all three. ``verdict`` is ``holds`` when the whole interval
  is above 0, ``flips`` when it is below 0, ``unclear`` when it covers 0 (or has < 2 days).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..common.atomic_files import atomic_write_text, atomic_write_with
from ..tasks.base import DEFAULT_STEPS_PER_DAY, steps_per_day_of
from ..tasks.registry import DEFAULT_TASK, get_task
from .naming import is_trained
from .statistics import Interval, bootstrap_mean, bootstrap_mean_difference, start_days

SENSITIVITY_METRICS = (
    "cumulative_reward",
    "episode_cost",
    "physics_violation_rate",
    "artificial_liquidity_MWh",
    "episode_volume",
    "mean_slippage",
    "spatial_fairness_index",
    "max_drawdown",
)
SENSITIVITY_FILE = "sensitivity.csv"


def sensitivity_metrics(task: str = DEFAULT_TASK) -> tuple[str, ...]:
    """The metrics ``sensitivity.csv`` covers: the solar market's :data:`SENSITIVITY_METRICS`; for
    another task, the reward, the episode cost and its declared safety and utility metrics."""
    if task == DEFAULT_TASK:
        return SENSITIVITY_METRICS
    declared = [m.name for m in get_task(task).metrics if m.dimension in ("safety", "utility")]
    return tuple(dict.fromkeys(["cumulative_reward", "episode_cost", *declared]))


FINDINGS_FILE = "findings.csv"
SENSITIVITY_MD = "sensitivity.md"


def _days(frame: pd.DataFrame, steps_per_day: int) -> np.ndarray:
    return start_days(frame["start_hour"], steps_per_day)


def verdict(interval: Interval) -> str:
    if not (np.isfinite(interval.low) and np.isfinite(interval.high)):
        return "unclear"
    if interval.low > 0:
        return "holds"
    if interval.high < 0:
        return "flips"
    return "unclear"


def sensitivity_table(
    results: pd.DataFrame,
    axes: Sequence[str],
    resamples: int = 2000,
    task: str = DEFAULT_TASK,
    *,
    steps_per_day: int = DEFAULT_STEPS_PER_DAY,
) -> pd.DataFrame:
    """Mean and cluster-bootstrap interval of each metric (:func:`sensitivity_metrics`) per axis
    value, setting and policy (``steps_per_day``: the task's, whose start days the intervals resample)."""
    metrics = [m for m in sensitivity_metrics(task) if m in results.columns]
    rows = []
    for axis in axes:
        for (value, setting, policy), group in results.groupby([axis, "setting", "policy"], sort=False):
            days = _days(group, steps_per_day)
            for metric in metrics:
                iv = bootstrap_mean(group[metric].to_numpy(dtype=float), days, n_resamples=resamples)
                rows.append(
                    {
                        "axis": axis,
                        "value": value,
                        "setting": setting,
                        "policy": policy,
                        "metric": metric,
                        "mean": iv.estimate,
                        "ci_low": iv.low,
                        "ci_high": iv.high,
                        "episodes": len(group),
                        "start_days": len(np.unique(days)),
                    }
                )
    return pd.DataFrame(rows)


def _best(frame: pd.DataFrame, policies: Sequence[str]) -> str:
    means = frame[frame["policy"].isin(policies)].groupby("policy")["cumulative_reward"].mean()
    return str(means.idxmax())


def _difference(a: pd.DataFrame, b: pd.DataFrame, metric: str, resamples: int, steps_per_day: int) -> Interval:
    return bootstrap_mean_difference(
        a[metric].to_numpy(dtype=float),
        _days(a, steps_per_day),
        b[metric].to_numpy(dtype=float),
        _days(b, steps_per_day),
        n_resamples=resamples,
    )


def _point_findings(frame: pd.DataFrame, resamples: int, steps_per_day: int) -> list[dict]:
    rows: list[dict] = []

    def add(finding: str, detail: str, metric: str, iv: Interval) -> None:
        rows.append(
            {
                "finding": finding,
                "detail": detail,
                "metric": metric,
                "estimate": iv.estimate,
                "ci_low": iv.low,
                "ci_high": iv.high,
                "verdict": verdict(iv),
            }
        )

    main = frame[frame["setting"] == "main"]
    learned = sorted(p for p in main["policy"].unique() if is_trained(p))  # user agents are not "RL"
    baselines = get_task(DEFAULT_TASK).baselines()  # the paper findings compare the solar market's baselines
    heuristics = sorted(p for p in main["policy"].unique() if p in baselines)
    if learned and heuristics:
        rl, heuristic = _best(main, learned), _best(main, heuristics)
        iv = _difference(
            main[main["policy"] == rl], main[main["policy"] == heuristic], "cumulative_reward", resamples, steps_per_day
        )
        add("rl_over_heuristics", f"{rl} - {heuristic}", "cumulative_reward", iv)
    no_physics = frame[frame["setting"] == "no_physics"]
    rise = sorted(set(learned) & set(no_physics["policy"])) if "artificial_liquidity_MWh" in frame.columns else []
    for policy in rise:  # the solar market's finding: a task without artificial liquidity has none
        iv = _difference(
            no_physics[no_physics["policy"] == policy],
            main[main["policy"] == policy],
            "artificial_liquidity_MWh",
            resamples,
            steps_per_day,
        )
        add("artificial_liquidity_rise", f"{policy}: no_physics - main", "artificial_liquidity_MWh", iv)
    if "episode_cost" in frame.columns:
        for setting, group in frame[frame["policy"] == "ppo-lag"].groupby("setting", sort=False):
            limit = float(group["cost_limit"].iloc[0])
            iv = bootstrap_mean(
                limit - group["episode_cost"].to_numpy(dtype=float), _days(group, steps_per_day), n_resamples=resamples
            )
            add("cost_within_limit", f"ppo-lag ({setting}): D - cost with D = {limit:g}", "episode_cost", iv)
    return rows


def findings_table(
    results: pd.DataFrame, axes: Sequence[str], resamples: int = 2000, *, steps_per_day: int = DEFAULT_STEPS_PER_DAY
) -> pd.DataFrame:
    """The paper's findings re-tested at every point (see the module docstring; ``steps_per_day``:
    the task's, whose start days the intervals resample)."""
    rows = []
    for point, frame in results.groupby("point", sort=False):
        values = {axis: frame[axis].iloc[0] for axis in axes}
        for row in _point_findings(frame, resamples, steps_per_day):
            rows.append({"point": point, **values, **row})
    return pd.DataFrame(rows)


def _markdown(frame: pd.DataFrame, digits: int = 4) -> str:
    if frame.empty:
        return "(none)\n"
    header = "| " + " | ".join(frame.columns) + " |\n|" + "---|" * len(frame.columns) + "\n"
    lines = []
    for row in frame.itertuples(index=False):
        cells = [f"{v:.{digits}g}" if isinstance(v, float) else str(v) for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return header + "\n".join(lines) + "\n"


def write_sensitivity(
    results: pd.DataFrame,
    axes: Sequence[str],
    out_dir: Path,
    resamples: int = 2000,
    task: str = DEFAULT_TASK,
) -> dict:
    """Write ``sensitivity.csv``, ``findings.csv`` and ``sensitivity.md`` into ``out_dir`` (``task``:
    the sweep's, whose metrics the tables cover and whose start days the intervals resample,
    :func:`~solarchain_eval.tasks.base.steps_per_day_of`)."""
    out = Path(out_dir)
    steps_per_day = steps_per_day_of(get_task(task))
    table = sensitivity_table(results, axes, resamples, task, steps_per_day=steps_per_day)
    findings = findings_table(results, axes, resamples, steps_per_day=steps_per_day)
    atomic_write_with(out / SENSITIVITY_FILE, lambda tmp: table.to_csv(tmp, index=False))
    atomic_write_with(out / FINDINGS_FILE, lambda tmp: findings.to_csv(tmp, index=False))
    focus = table[table["metric"].isin(["cumulative_reward", "episode_cost", "artificial_liquidity_MWh"])]
    text = (
        "# Sweep sensitivity\n\nMeans with 95 % cluster-bootstrap intervals over start days.\n\n"
        "## Where the paper's findings hold or flip\n\n"
        + _markdown(findings)
        + "\n## Reward, episode cost and artificial liquidity against each axis\n\n"
        + _markdown(focus)
    )
    atomic_write_text(out / SENSITIVITY_MD, text)
    return {"sensitivity": len(table), "findings": len(findings)}
