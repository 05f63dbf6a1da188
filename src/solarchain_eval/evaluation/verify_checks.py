"""The checks :mod:`.verify` makes of a run's record: its files, its protocol, its rollouts, its
dataset, and how a re-run episode's ``metrics.csv`` row compares with the recorded one.

:func:`rollout_set_problem` is the one rule of which rollouts a run holds, shared with the
leaderboard (:mod:`solarchain_eval.report.leaderboard.inputs`): exactly one row per (policy, run
seed, episode) of the protocol, none missing, none repeated, none outside it.

Rows are compared as text, cell by cell, as the run's CSV writer writes them (floats as their
shortest round-trip repr, so equal text is the same float64); a cell whose text differs only
because another row turned an integer column to float is compared as float64.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..common.errors import InputDataError, NamesOptions
from ..records_schema import (
    AGENT_COLUMN_PREFIX,
    EPISODE_KEYS,
    REMOVED_COLUMNS,
    RENAMED_COLUMNS,
    record_columns,
)
from ..tasks.base import Task, metric_names
from ..tasks.registry import get_task
from .fingerprint import protocol_fingerprint, protocol_id
from .records import METADATA_FILE, METRICS_FILE, REPORT_DIR, metrics_frame
from .rollout import EpisodeResult
from .run_metadata import RunMetadata, RunMetadataError
from .rundir import verify_files


class VerifyError(NamesOptions, InputDataError, ValueError):
    """A verification that cannot start: no run directory or metadata, or unusable options."""


@dataclass(frozen=True)
class Difference:
    """The first cell of a re-run episode that differs from the recorded ``metrics.csv`` row."""

    run_seed: int
    episode: int
    metric: str
    recorded: str
    rerun: str


def read_metadata(run_dir: Path) -> RunMetadata:
    """``run_dir/run_metadata.json`` (a :class:`VerifyError` when absent, unreadable or malformed)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise VerifyError(f"{run_dir}: no such run directory")
    path = run_dir / METADATA_FILE
    if not path.is_file():
        raise VerifyError(f"{run_dir} has no {METADATA_FILE}: nothing records what the run was")
    try:
        return RunMetadata.read(path)
    except RunMetadataError as error:
        raise VerifyError(str(error)) from None


def run_task(metadata: RunMetadata) -> Task:
    """The run's task, by its recorded name, from the tasks installed here (a :class:`VerifyError`
    when none has that name: a run never names the code verify loads)."""
    try:
        return metadata.resolve_task()
    except RunMetadataError as error:
        raise VerifyError(str(error)) from None


def check_checksums(run_dir: Path, metadata: RunMetadata, grid_files: Sequence[str] = ()) -> list[str]:
    """Problems of every file in ``run_dir`` against the metadata's sha256 (empty: all match).

    Every recorded file must be there with its sha256, and every other entry of the directory
    (but ``run_metadata.json`` and ``grid_files``) is named as extra.
    """
    run_dir = Path(run_dir)
    path = run_dir / METADATA_FILE
    problems = [] if metadata.complete else [f"{path} does not mark the run complete"]
    skipped = {METADATA_FILE, *grid_files}
    # The report's folder (``solarchain-eval report RUN``) is derived from the vouched files.
    entries = sorted(p for p in run_dir.iterdir() if p.name not in skipped and not _is_report_dir(p))
    problems += verify_files(run_dir, metadata.files, path, [p.name for p in entries if p.is_file()])
    problems += [f"{p} is not a file and is not vouched for by {METADATA_FILE}" for p in entries if not p.is_file()]
    return problems


def _is_report_dir(path: Path) -> bool:
    return path.name == REPORT_DIR and path.is_dir()


def check_protocol(metadata: RunMetadata, config: Any, task: Task | None = None) -> list[str]:
    """Where the recorded fingerprint disagrees with its id or with the rest of the metadata
    (``config``: the run's task configuration; ``task``: default the run's)."""
    recorded = metadata.protocol
    if not metadata.protocol_recorded or recorded is None:  # one computed on read vouches for nothing
        return ["run_metadata.json records no protocol fingerprint (written by an older version?)"]
    problems = []
    if protocol_id(recorded) != metadata.protocol_id:
        problems.append(f"protocol_id {metadata.protocol_id!r} is not the id of the recorded fingerprint")
    expected = protocol_fingerprint(
        dataset_sha256=metadata.dataset.files,
        run_seeds=metadata.run_seeds,
        episodes=metadata.episodes,
        episode_seed_rule=str(recorded.get("episode_seed_rule")),
        setting=metadata.setting,
        config=config,
        action_modes=recorded.get("action_modes") or {},
        task=task or metadata.resolve_task(),
    )
    for key in sorted(set(expected) | set(recorded)):
        if expected.get(key) != recorded.get(key):
            problems.append(
                f"fingerprint field {key!r} is {recorded.get(key)!r}; this version and the metadata give {expected.get(key)!r}"
            )
    return problems


def dataset_problem(data_dir: Path, recorded: Mapping[str, str], task: Task | None = None) -> str | None:
    """Why ``data_dir`` is not the recorded dataset of ``task`` (default: the solar market; None: the
    same files, each with the recorded sha256)."""
    task = task or get_task()
    try:
        found = task.provenance(task.load_data(data_dir))["files"]
    except (ValueError, OSError) as error:  # no dataset there, or a broken one
        return f"{data_dir} is not a readable dataset ({str(error).splitlines()[0]})"
    for name in sorted(set(recorded) | set(found)):
        path = Path(data_dir) / name
        if name not in found:
            return f"{path} is missing"
        if name not in recorded:
            return f"{path} is not part of the recorded dataset"
        if found[name] != recorded[name]:
            return f"{path} does not have the recorded sha256"
    return None


def resolve_dataset(metadata: RunMetadata, data_dir: Path | None, task: Task | None = None) -> tuple[Path | None, str]:
    """The dataset to re-run on and, when there is none, why.

    ``data_dir`` (when given) must hold the recorded CSVs (a :class:`VerifyError` otherwise);
    else the recorded ``data_dir`` is used if its CSVs still have the recorded sha256. A task
    without a dataset (``data_dir`` recorded as None, no files) re-runs on none: ``(None, "")``.
    """
    task = task or metadata.resolve_task()
    recorded = metadata.dataset.files
    if metadata.dataset.data_dir is None and not recorded:
        if data_dir is not None:
            raise VerifyError.about(
                "{opt_data_dir} {path}: the run's task {task!r} has no dataset", path=data_dir, task=task.name
            )
        return None, ""
    if not recorded:
        return None, "the run records no dataset sha256"
    if data_dir is not None:
        problem = dataset_problem(data_dir, recorded, task)
        if problem is not None:
            raise VerifyError.about(
                "{opt_data_dir} {path} is not the run's dataset: {problem}", path=data_dir, problem=problem
            )
        return Path(data_dir), ""
    recorded_dir = Path(str(metadata.dataset.data_dir))
    problem = dataset_problem(recorded_dir, recorded, task) if recorded_dir.is_dir() else f"{recorded_dir} is missing"
    if problem is not None:
        return None, f"dataset: {problem}; pass --data DIR with the recorded CSVs"
    return recorded_dir, ""


#: One rollout: (policy, run seed, episode).
RolloutKey = tuple[str, int, int]


def rollout_set_problem(
    keys: Iterable[RolloutKey], policies: Sequence[str], run_seeds: Sequence[int], episodes: int
) -> str | None:
    """Why ``keys`` (every row's rollout, in file order) is not exactly the protocol's rollouts:
    each of ``policies`` × ``run_seeds`` × ``episodes`` once (None: it is).

    The first problem is named: a repeated rollout, a policy the run does not list, a rollout
    outside the protocol, or a policy missing rollouts (with the first one missing).
    """
    seeds = [int(s) for s in run_seeds]
    promise = f"run seeds {seeds} × {int(episodes)} episodes"
    seen: set[RolloutKey] = set()
    for policy, seed, episode in keys:
        key = (str(policy), int(seed), int(episode))
        if key in seen:
            return f"rollout (policy {key[0]!r}, run seed {key[1]}, episode {key[2]}) appears more than once"
        seen.add(key)
    listed = [str(p) for p in policies]
    expected = {(p, s, e) for p in listed for s in seeds for e in range(int(episodes))}
    for policy, seed, episode in sorted(seen - expected):
        if policy not in listed:
            return f"policy {policy!r} has rows but is not one of the run's policies ({', '.join(listed)})"
        return f"policy {policy!r} holds rollout (run seed {seed}, episode {episode}) outside its protocol ({promise})"
    for policy in listed:
        missing = sorted(k for k in expected - seen if k[0] == policy)
        if missing:
            held = sum(1 for k in seen if k[0] == policy)
            _, seed, episode = missing[0]
            return (
                f"policy {policy!r} holds {held} of the {len(expected) // len(listed)} rollouts its protocol promises "
                f"({promise}); missing: run seed {seed}, episode {episode}"
            )
    return None


def read_metrics_rows(path: Path) -> list[dict[str, str]]:
    """``metrics.csv`` rows as written (cell text), in file order, with integer run seeds and episodes.

    Raises
    ------
    ValueError
        A row whose ``run_seed`` or ``episode`` is not an integer (the message names the row).
    """
    with open(path, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    for number, row in enumerate(rows, start=2):
        for column in ("policy", "run_seed", "episode"):
            value = row.get(column)
            if value is None or (column != "policy" and not value.strip().lstrip("-").isdigit()):
                raise ValueError(
                    f"{path} row {number}: {column} {value!r} is not {'a name' if column == 'policy' else 'an integer'}"
                )
    return rows


def check_rollouts(metadata: RunMetadata, rows: Sequence[Mapping[str, str]]) -> list[str]:
    """Whether ``metrics.csv``'s ``rows`` are exactly the run's rollouts (:func:`rollout_set_problem`)
    and as many as ``run_metadata.json`` records (empty: they are)."""
    problems = []
    recorded = metadata.rows.get("metrics")
    if recorded is not None and recorded != len(rows):
        problems.append(f"{METRICS_FILE} holds {len(rows)} rows; {METADATA_FILE} records {recorded}")
    problem = rollout_set_problem(
        ((r["policy"], int(r["run_seed"]), int(r["episode"])) for r in rows),
        metadata.policies,
        metadata.run_seeds,
        metadata.episodes,
    )
    return problems + ([f"{METRICS_FILE}: {problem}"] if problem else [])


def column_problems(header: Sequence[str], task: Task) -> list[str]:
    """Where ``metrics.csv``'s ``header`` is not the record schema of ``task``: a missing episode key
    or declared metric, a column neither the schema (:func:`~solarchain_eval.records_schema.record_columns`
    of the task's metrics, older names included) nor a user agent's (``agent_*``) defines."""
    known = record_columns(tuple(m.column for m in task.metrics))
    missing = [c for c in (*EPISODE_KEYS, *metric_names(task)) if c not in header]
    unknown = [
        c
        for c in header
        if c not in known
        and c not in RENAMED_COLUMNS
        and c not in REMOVED_COLUMNS
        and not c.startswith(AGENT_COLUMN_PREFIX)
    ]
    problems = [f"{METRICS_FILE} lacks column {c!r} of task {task.name!r}" for c in missing[:1]]
    return problems + [
        f"{METRICS_FILE} has column {c!r}, which task {task.name!r} does not declare" for c in unknown[:1]
    ]


def read_rollouts(
    run_dir: Path, metadata: RunMetadata, task: Task | None = None
) -> tuple[dict[RolloutKey, dict[str, str]], list[str]]:
    """``run_dir``'s ``metrics.csv`` rows by rollout and the problems of its rollout set (:func:`check_rollouts`)
    and of its columns (:func:`column_problems`, ``task``: default the run's).

    The rows are returned only when there is no problem (a repeated key would hide a row);
    a missing file is no problem here (the checksums name it).
    """
    path = Path(run_dir) / METRICS_FILE
    if not path.is_file():
        return {}, []
    try:
        rows = read_metrics_rows(path)
        with open(path, newline="", encoding="utf-8") as handle:
            header = next(csv.reader(handle), [])
    except (ValueError, OSError) as error:
        return {}, [str(error)]
    problems = column_problems(header, task or metadata.resolve_task()) + check_rollouts(metadata, rows)
    return ({} if problems else {(r["policy"], int(r["run_seed"]), int(r["episode"])): r for r in rows}), problems


def keeper_models(metadata: RunMetadata, given: Mapping[str, Path], within: Path | None) -> dict[str, Path]:
    """The model files verify may load: those the keeper passed (``given``, ``--models``) and, for
    the units of a grid root the keeper named (``within``), the recorded ones that lie inside it.

    A run's own record never sends verify to a path outside what the keeper named.
    """
    models = {str(k): Path(v) for k, v in given.items()}
    if within is not None:
        root = Path(within).resolve()
        for name, path in metadata.models.items():
            resolved = Path(path).resolve()
            if str(name) not in models and resolved.is_relative_to(root):
                models[str(name)] = resolved
    return models


def written_row(result: EpisodeResult, task: Task | None = None) -> dict[str, str]:
    """The re-run episode's ``metrics.csv`` row as the run's CSV writer writes it (cell text)."""
    text = metrics_frame([result], task).to_csv()
    (row,) = list(csv.DictReader(io.StringIO(text)))
    row.pop("", None)  # the index column
    return row


def same_cell(recorded: str, rerun: str) -> bool:
    """Equal text, or (an integer column that another row turned to float) the same float64."""
    if recorded == rerun:
        return True
    try:
        a, b = float(recorded or "nan"), float(rerun or "nan")
    except ValueError:
        return False
    return a == b or (math.isnan(a) and math.isnan(b))


def first_difference(
    recorded: Mapping[str, str], rerun: Mapping[str, str], run_seed: int, episode: int
) -> Difference | None:
    for column in [*recorded, *(c for c in rerun if c not in recorded)]:
        old, new = recorded.get(column), rerun.get(column)
        if (old is None and new == "") or (new is None and old == ""):
            continue  # a column that only another policy of the run fills (e.g. the llm-agent's)
        if old is None or new is None or not same_cell(old, new):
            absent = "(no such column)"
            return Difference(run_seed, episode, column, absent if old is None else old, absent if new is None else new)
    return None
