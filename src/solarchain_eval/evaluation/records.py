"""Tables of evaluation records (metrics, actions, city-hour) and their on-disk files."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..agents.validation import AGENT_EXTRAS_KEY
from ..common.atomic_files import atomic_write_csv, atomic_write_json, atomic_write_text
from ..governance.wrapper import EXTRA_DIAGNOSTICS_KEY, EXTRA_LOG_KEY, EXTRA_METRICS_KEY
from ..records_schema import DIAGNOSTIC_NAMES, EPISODE_KEYS
from ..tasks.base import Task, metric_names
from ..tasks.governance_view import diagnostic_names_of, governance_view_of
from ..tasks.registry import get_task
from .rollout import EpisodeResult

METRICS_FILE = "metrics.csv"
ACTIONS_FILE = "actions.csv"
CITY_HOUR_FILE = "city_hour_policy.csv"
#: The per-step tables in Parquet (``evaluate --step-format parquet``), in place of the two CSVs.
ACTIONS_PARQUET = "actions.parquet"
CITY_HOUR_PARQUET = "city_hour_policy.parquet"
#: Each per-step CSV's Parquet twin (readers take whichever a run has).
PARQUET_TWINS = {ACTIONS_FILE: ACTIONS_PARQUET, CITY_HOUR_FILE: CITY_HOUR_PARQUET}
SUMMARY_FILE = "summary.json"
METADATA_FILE = "run_metadata.json"
AGENTIC_LOG_FILE = "agentic_logs.jsonl"
DIAGNOSTICS_FILE = "governance_diagnostics.csv"
#: The folder ``report`` writes into a run directory or a paper root by default: derived from the
#: run's files, so not among the files ``run_metadata.json`` vouches for.
REPORT_DIR = "report"


def metrics_frame(results: Sequence[EpisodeResult], task: Task | None = None) -> pd.DataFrame:
    """One row per episode: identifiers, the task's episode metrics (``task.metrics``, default the
    solar market's, docs/metrics.md), then any extra per-episode metrics (the Planner/Auditor
    layer's, the LLM agent's) and a user agent's own ``agent_*`` columns. The identifiers and
    metrics are the runner's: written last, so no extra column can replace them."""
    rows = []
    for r in results:
        row = {**r.extras.get(EXTRA_METRICS_KEY, {}), **r.extras.get(AGENT_EXTRAS_KEY, {})}
        row.update({k: getattr(r, k) for k in EPISODE_KEYS})
        row.update(r.metrics)
        rows.append(row)
    frame = pd.DataFrame(rows)
    # the metric columns in the task's declared order (an episode's metrics come in that order)
    metrics = metric_names(task) if task is not None else tuple(results[0].metrics) if results else None
    if metrics is None:
        metrics = metric_names(get_task())
    if frame.empty:
        return pd.DataFrame(columns=[*EPISODE_KEYS, *metrics])
    ordered = [*EPISODE_KEYS, *metrics]
    return frame[ordered + [c for c in frame.columns if c not in ordered]]


def actions_frame(results: Sequence[EpisodeResult], task: Task | None = None) -> pd.DataFrame:
    """One row per step: identifiers and the task's per-step fields (``task.step_fields``, default the
    solar market's)."""
    columns: dict[str, Any] = {}
    lengths = [r.n_steps for r in results]
    for key in ("policy", "setting", "run_seed", "episode", "episode_seed"):
        columns[key] = np.repeat([getattr(r, key) for r in results], lengths)
    columns["step"] = np.concatenate([np.arange(n) for n in lengths]) if results else np.zeros(0, dtype=int)
    for name in (task or get_task()).step_fields:
        columns[name] = [value for r in results for value in r.steps[name]]
    return pd.DataFrame(columns)


def city_hour_frame(results: Sequence[EpisodeResult], cities: Sequence[str], task: Task | None = None) -> pd.DataFrame:
    """One row per step and step extra (the solar market: per city): the step's hour columns
    (``absolute_hour``, ``hour``, those of the task's step fields), the extra's name (``city``) and
    value (``city_reward``), and the executed action (the task's levers; default the solar market's)."""
    task = task or get_task()
    n_cities = len(cities)
    keys: dict[str, list] = {k: [] for k in ("policy", "setting", "run_seed", "episode")}
    hours = [c for c in ("absolute_hour", "hour") if c in task.step_fields]
    levers = [lever.name for lever in task.levers]
    per_step: dict[str, list] = {c: [] for c in (*hours, *levers)}
    step, city_reward = [], []
    for r in results:
        n = r.n_steps
        for key in keys:
            keys[key].extend([getattr(r, key)] * (n * n_cities))
        for t in range(n):
            step.extend([t] * n_cities)
            for column, values in per_step.items():
                values.extend([r.steps[column][t]] * n_cities)
            city_reward.extend(r.city_rewards[t])
    city = list(cities) * (len(step) // n_cities if n_cities else 0)
    return pd.DataFrame(
        {
            **keys,
            "step": step,
            **{c: per_step[c] for c in hours},
            "city": city,
            "city_reward": city_reward,
            **{c: per_step[c] for c in levers},
        }
    )


def agentic_log_text(results: Sequence[EpisodeResult]) -> str | None:
    """JSON Lines of every agentic step row (episode identifiers first), or None if none."""
    if not any(EXTRA_LOG_KEY in r.extras for r in results):
        return None
    lines = []
    for r in results:
        ids = {
            "policy": r.policy,
            "setting": r.setting,
            "run_seed": r.run_seed,
            "episode": r.episode,
            "episode_seed": r.episode_seed,
        }
        for row in r.extras.get(EXTRA_LOG_KEY, ()):
            lines.append(json.dumps({**ids, **row}, ensure_ascii=False, allow_nan=False))
    return "".join(line + "\n" for line in lines)


def diagnostic_names(task: Task | None = None) -> tuple[str, ...]:
    """The ``governance_diagnostics.csv`` columns after the episode keys, ``planner`` and
    ``auditor`` for ``task``'s market: its governance view's outcome names
    (:func:`~solarchain_eval.tasks.governance_view.diagnostic_names_of`; None: the solar market's)."""
    return DIAGNOSTIC_NAMES if task is None else diagnostic_names_of(governance_view_of(task))


def diagnostics_csv(results: Sequence[EpisodeResult], task: Task | None = None) -> str | None:
    """:func:`diagnostics_frame` as CSV text, written row by row with the csv module (what pandas
    writes for these columns: floats as ``repr``, None empty; several times faster)."""
    if not any(EXTRA_DIAGNOSTICS_KEY in r.extras for r in results):
        return None
    ids = EPISODE_KEYS
    columns = diagnostic_names(task)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([*ids, "planner", "auditor", *columns])
    for r in results:
        metrics = r.extras.get(EXTRA_METRICS_KEY, {})
        head = [*(getattr(r, k) for k in ids), metrics.get("planner"), metrics.get("auditor")]
        for row in r.extras.get(EXTRA_DIAGNOSTICS_KEY, ()):
            writer.writerow([*head, *(row[c] for c in columns)])
    return buffer.getvalue()


def diagnostics_frame(results: Sequence[EpisodeResult], task: Task | None = None) -> pd.DataFrame | None:
    """One row per governed step with its counterfactual outcomes (docs/governance.md), columns
    named by ``task``'s governance view (None: the solar market's), or None when no episode
    recorded diagnostics."""
    if not any(EXTRA_DIAGNOSTICS_KEY in r.extras for r in results):
        return None
    ids = EPISODE_KEYS
    rows = []
    for r in results:
        metrics = r.extras.get(EXTRA_METRICS_KEY, {})
        head = {**{k: getattr(r, k) for k in ids}, "planner": metrics.get("planner"), "auditor": metrics.get("auditor")}
        rows.extend({**head, **row} for row in r.extras.get(EXTRA_DIAGNOSTICS_KEY, ()))
    return pd.DataFrame(rows, columns=[*ids, "planner", "auditor", *diagnostic_names(task)])


def _finite_or_none(value: float) -> float | None:
    return value if np.isfinite(value) else None


def summarize(metrics: pd.DataFrame) -> list[dict[str, Any]]:
    """Per (policy, setting): n, distinct episodes behind it, and mean/std/min/max of each metric
    the policy has (a column only other policies of the run write, e.g. the LLM agent's, is left out).

    ``std`` is the sample standard deviation (ddof=1), as in the paper's tables. Of a single
    episode it is undefined: NaN, written as ``null`` (strict JSON), as the report's
    :func:`~solarchain_eval.report.statistics.mean_std` has NaN (docs/metrics.md#summaries).
    """
    if metrics.empty:
        return []
    summary = []
    numeric = [c for c in metrics.columns if c not in EPISODE_KEYS and pd.api.types.is_numeric_dtype(metrics[c])]
    static_slippage = {
        setting: float(group["mean_slippage"].mean())
        for (policy, setting), group in metrics.groupby(["policy", "setting"], sort=False)
        if policy == "static" and "mean_slippage" in group  # the solar market's slippage column
    }
    for (policy, setting), group in metrics.groupby(["policy", "setting"], sort=False):
        entry: dict[str, Any] = {
            "policy": policy,
            "setting": setting,
            "episodes": int(len(group)),
            "run_seeds": sorted(int(s) for s in group["run_seed"].unique()),
            "distinct_episode_seeds": int(group["episode_seed"].nunique()),
            "distinct_start_hours": int(group["start_hour"].nunique()),
            "metrics": {
                name: {
                    "mean": float(group[name].mean()),
                    "std": _finite_or_none(float(group[name].std(ddof=1))),
                    "min": float(group[name].min()),
                    "max": float(group[name].max()),
                }
                for name in numeric
                if group[name].notna().any()  # a column another policy adds (the LLM agent's) is absent here
            },
        }
        if setting in static_slippage and "mean_slippage" in group:
            base = static_slippage[setting]
            entry["slippage_reduction_vs_static"] = (base - float(group["mean_slippage"].mean())) / max(base, 1e-9)
        summary.append(entry)
    return summary


def write_records(
    run_dir: Path, results: Sequence[EpisodeResult], cities: Sequence[str], task: Task | None = None
) -> dict[str, Path]:
    """Write metrics, actions and city-hour CSVs (the last only when the task names step extras,
    ``cities``), the agentic log (agentic runs only) and the summary, each file atomically."""
    metrics = metrics_frame(results, task)
    paths = {
        METRICS_FILE: atomic_write_csv(run_dir / METRICS_FILE, metrics),
        ACTIONS_FILE: atomic_write_csv(run_dir / ACTIONS_FILE, actions_frame(results, task)),
    }
    if cities:
        paths[CITY_HOUR_FILE] = atomic_write_csv(run_dir / CITY_HOUR_FILE, city_hour_frame(results, cities, task))
    log = agentic_log_text(results)
    if log is not None:
        paths[AGENTIC_LOG_FILE] = atomic_write_text(run_dir / AGENTIC_LOG_FILE, log)
    diagnostics = diagnostics_csv(results, task)
    if diagnostics is not None:
        paths[DIAGNOSTICS_FILE] = atomic_write_text(run_dir / DIAGNOSTICS_FILE, diagnostics)
    paths[SUMMARY_FILE] = atomic_write_json(run_dir / SUMMARY_FILE, summarize(metrics))
    return paths
