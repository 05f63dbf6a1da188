"""Evaluate agents over every task of a suite (docs/suites.md): one run per entry, then the suite root.

Layout of a suite root ``OUT``:

- ``OUT/<entry>/``: an ordinary run directory per entry (the same files and protocol as
  ``evaluate --data <the entry's dataset>``), the agents and the suite's two reference baselines;
- ``OUT/suite_scores.csv``: one row per policy, entry and episode, with the raw and normalised score;
- ``OUT/performance_profile.png``: the performance profile of every policy;
- ``OUT/suite_metadata.json``: the suite, its protocol id, the per-entry and aggregate scores, and
  the sha256 of every file above (each run's ``run_metadata.json``, which itself holds the sha256s
  of its run's files). Written last, atomically: a root without it is unfinished.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..common.atomic_files import atomic_write_csv, atomic_write_json, read_csv_exact, sha256_file
from ..common.errors import InputDataError
from ..common.redaction import redact_command
from ..common.versions import git_commit, package_versions
from ..tasks.base import Task
from ..tasks.registry import get_task
from ..tasks.suites import Suite, SuiteEntry, get_suite
from .fingerprint import canonical_json, sha256_text
from .records import METADATA_FILE, METRICS_FILE
from .run_spec import EvaluationOutcome, EvaluationSpec
from .rundir import check_target
from .suite_stats import BOOTSTRAP_REPS, BOOTSTRAP_SEED, aggregate_table, improvement_table, performance_profile_figure

SUITE_METADATA_FILE = "suite_metadata.json"
SUITE_SCORES_FILE = "suite_scores.csv"
PROFILE_FILE = "performance_profile.png"
#: The episode identifiers a score is aligned on across entries (the rows of an agent's score matrix).
EPISODE_ROW = ("run_seed", "episode")


class SuiteScoreError(InputDataError, ValueError):
    """A suite's scores cannot be normalised or aggregated (the message names the entry)."""


@dataclass
class SuiteEvaluation:
    """What a suite evaluation returns (and ``suite_metadata.json`` records).

    Attributes
    ----------
    suite : str
    protocol_id : str
        The suite protocol's short id: equal ids, comparable suite results.
    protocol : dict
        What the id hashes: the entries' run protocol ids (sorted), the score, the normalisation and the splits.
    scores : pandas.DataFrame
        One row per policy, entry and episode: ``entry``, ``split``, ``policy``, ``run_seed``, ``episode``,
        ``score`` and ``normalised``.
    tasks : pandas.DataFrame
        One row per entry and policy: the mean raw and normalised score.
    aggregates : pandas.DataFrame
        One row per policy: IQM, mean, median and optimality gap of the normalised scores, each with its
        stratified-bootstrap 95 % interval (``<name>_low``, ``<name>_high``).
    improvement : pandas.DataFrame
        P(policy > over) for every ordered pair of policies.
    runs : dict
        Entry name -> its :class:`~.runner.EvaluationOutcome`.
    root : Path or None
        The suite root (None when nothing was kept).
    wall_s : float
    """

    suite: str
    protocol_id: str
    protocol: dict[str, Any]
    scores: pd.DataFrame
    tasks: pd.DataFrame
    aggregates: pd.DataFrame
    improvement: pd.DataFrame
    runs: dict[str, EvaluationOutcome] = field(repr=False)
    root: Path | None
    wall_s: float


def score_metric(task: Task) -> str:
    """The metric a suite scores a task by: its first declared utility metric where higher is better."""
    for metric in task.metrics:
        if metric.dimension == "utility" and metric.direction == "higher":
            return metric.name
    raise SuiteScoreError(f"task {task.name!r} declares no utility metric where higher is better")


def normalisation_rule(suite: Suite) -> str:
    low, high = suite.reference
    return f"per entry: (score - mean score of {low}) / (mean score of {high} - mean score of {low})"


def run_suite(
    suite: str | Suite,
    policies: Sequence[Any],
    make_spec: Callable[[SuiteEntry, Path, list[Any]], EvaluationSpec],
    run: Callable[[EvaluationSpec, Path], EvaluationOutcome],
    out: Path,
    *,
    overwrite: bool = False,
    command: Sequence[str] | None = None,
    reps: int = BOOTSTRAP_REPS,
    seed: int = BOOTSTRAP_SEED,
) -> SuiteEvaluation:
    """Run ``policies`` (and the suite's reference baselines) on every entry of ``suite`` into ``out``.

    ``make_spec(entry, data_dir, policies)`` builds an entry's evaluation; ``run(spec, run_dir)``
    runs and publishes it (:func:`~.runner.run_evaluation` with the caller's progress and options).

    Raises
    ------
    UnknownSuiteError
        An unknown suite name (before anything is written).
    RunDirError
        ``out`` holds anything and ``overwrite`` is not set (before anything is written).
    SuiteScoreError
        An entry's reference baselines score the same, or the entries' episodes differ.
    """
    suite = get_suite(suite) if isinstance(suite, str) else suite
    out = Path(out)
    check_target(out, overwrite=overwrite)
    started = time.perf_counter()
    started_at = datetime.now(UTC).isoformat(timespec="seconds")
    (out / SUITE_METADATA_FILE).unlink(missing_ok=True)  # an overwritten root is unfinished until the end
    everyone = suite.with_reference(policies)
    runs: dict[str, EvaluationOutcome] = {}
    frames = []
    for entry in suite.entries:
        spec = make_spec(entry, entry.data_dir(), everyone)
        runs[entry.name] = run(spec, out / entry.name)
        frames.append(entry_scores(entry, read_csv_exact(out / entry.name / METRICS_FILE), suite))
    scores = pd.concat(frames, ignore_index=True)
    result = summarise(suite, scores, runs, reps=reps, seed=seed)
    result.root = out
    result.wall_s = time.perf_counter() - started
    atomic_write_csv(out / SUITE_SCORES_FILE, scores)
    performance_profile_figure(matrices(scores), out / PROFILE_FILE, f"suite {suite.name}: performance profile")
    atomic_write_json(out / SUITE_METADATA_FILE, suite_metadata(suite, result, out, started_at, command, reps, seed))
    return result


def entry_scores(entry: SuiteEntry, metrics: pd.DataFrame, suite: Suite) -> pd.DataFrame:
    """One entry's per-episode raw and normalised scores (on the entry's own reference baselines)."""
    metric = score_metric(get_task(entry.task))
    low_name, high_name = suite.reference
    means = metrics.groupby("policy")[metric].mean()
    low, high = float(means[low_name]), float(means[high_name])
    if high == low:
        raise SuiteScoreError(
            f"suite {suite.name!r}, entry {entry.name!r}: {high_name} and {low_name} have the same mean {metric} "
            f"({low}); the normalised score is undefined"
        )
    frame = metrics[["policy", *EPISODE_ROW]].copy()
    frame.insert(0, "split", entry.split)
    frame.insert(0, "entry", entry.name)
    frame["score"] = metrics[metric].astype(float)
    frame["normalised"] = (frame["score"] - low) / (high - low)
    return frame


def matrices(scores: pd.DataFrame) -> dict[str, np.ndarray]:
    """Policy -> its normalised score matrix: one row per (run seed, episode), one column per entry."""
    entries = list(dict.fromkeys(scores["entry"]))
    out = {}
    for policy, group in scores.groupby("policy", sort=False):
        table = group.pivot(index=list(EPISODE_ROW), columns="entry", values="normalised")[entries]
        if table.isna().any().any():
            raise SuiteScoreError(f"policy {policy!r}: the entries of the suite ran different episodes")
        out[str(policy)] = table.to_numpy(dtype=float)
    return out


def suite_protocol(suite: Suite, runs: dict[str, EvaluationOutcome]) -> dict[str, Any]:
    """What the suite protocol id hashes (see :class:`SuiteEvaluation`)."""
    return {
        "protocol_ids": sorted(outcome.protocol_id for outcome in runs.values()),
        "score": sorted({score_metric(get_task(entry.task)) for entry in suite.entries}),
        "normalisation": normalisation_rule(suite),
        "splits": list(suite.splits),
    }


def summarise(
    suite: Suite, scores: pd.DataFrame, runs: dict[str, EvaluationOutcome], *, reps: int, seed: int
) -> SuiteEvaluation:
    """The per-entry means, aggregates and probabilities of improvement of a suite's scores."""
    per_policy = matrices(scores)
    protocol = suite_protocol(suite, runs)
    tasks = scores.groupby(["entry", "split", "policy"], sort=False)[["score", "normalised"]].mean().reset_index()
    return SuiteEvaluation(
        suite=suite.name,
        protocol_id=sha256_text(canonical_json(protocol))[:12],
        protocol=protocol,
        scores=scores,
        tasks=tasks,
        aggregates=pd.DataFrame(aggregate_table(per_policy, reps=reps, seed=seed)),
        improvement=pd.DataFrame(improvement_table(per_policy)),
        runs=runs,
        root=None,
        wall_s=0.0,
    )


def suite_metadata(
    suite: Suite,
    result: SuiteEvaluation,
    out: Path,
    started_at: str,
    command: Sequence[str] | None,
    reps: int,
    seed: int,
) -> dict[str, Any]:
    """The suite root's ``suite_metadata.json``."""
    files = {entry.name: f"{entry.name}/{METADATA_FILE}" for entry in suite.entries}
    return {
        "suite": suite.name,
        "description": suite.description,
        "protocol_id": result.protocol_id,
        "protocol": result.protocol,
        "reference": list(suite.reference),
        "entries": [
            {
                "name": entry.name,
                "task": entry.task,
                "split": entry.split,
                "run_dir": entry.name,
                "protocol_id": result.runs[entry.name].protocol_id,
                "setting": str(result.runs[entry.name].summary[0]["setting"])
                if result.runs[entry.name].summary
                else None,
            }
            for entry in suite.entries
        ],
        "tasks": result.tasks.to_dict(orient="records"),
        "aggregates": result.aggregates.to_dict(orient="records"),
        "probability_of_improvement": result.improvement.to_dict(orient="records"),
        "bootstrap": {"reps": reps, "seed": seed, "interval": 0.95, "method": "percentile, stratified by entry"},
        "sha256": {
            SUITE_SCORES_FILE: sha256_file(out / SUITE_SCORES_FILE),
            PROFILE_FILE: sha256_file(out / PROFILE_FILE),
            **{path: sha256_file(out / path) for path in files.values()},
        },
        "started_at": started_at,
        "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "wall_s": round(result.wall_s, 3),
        "command": redact_command(list(command) if command is not None else sys.argv),
        "git_commit": git_commit(),
        "package_versions": package_versions(),
    }
