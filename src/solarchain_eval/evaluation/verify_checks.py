"""The checks :mod:`.verify` makes of a run's record: its files, its protocol, its dataset, and
how a re-run episode's ``metrics.csv`` row compares with the recorded one.

Rows are compared as text, cell by cell, as the run's CSV writer writes them (floats as their
shortest round-trip repr, so equal text is the same float64); a cell whose text differs only
because another row turned an integer column to float is compared as float64.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..common.errors import NamesOptions
from ..config import BenchmarkConfig
from ..data.provenance import dataset_provenance
from ..data.table import load_table
from .fingerprint import protocol_fingerprint, protocol_id
from .records import METADATA_FILE, REPORT_DIR, metrics_frame
from .rollout import EpisodeResult
from .rundir import verify_files


class VerifyError(NamesOptions, ValueError):
    """A verification that cannot start: no run directory or metadata, or unusable options."""


@dataclass(frozen=True)
class Difference:
    """The first cell of a re-run episode that differs from the recorded ``metrics.csv`` row."""

    run_seed: int
    episode: int
    metric: str
    recorded: str
    rerun: str


def read_metadata(run_dir: Path) -> dict[str, Any]:
    """``run_dir/run_metadata.json`` (a :class:`VerifyError` when absent or unreadable)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise VerifyError(f"{run_dir}: no such run directory")
    path = run_dir / METADATA_FILE
    if not path.is_file():
        raise VerifyError(f"{run_dir} has no {METADATA_FILE}: nothing records what the run was")
    try:
        metadata = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, OSError) as error:
        raise VerifyError(f"{path} is unreadable ({error})") from None
    if not isinstance(metadata, dict):
        raise VerifyError(f"{path} does not hold a JSON object")
    return metadata


def check_checksums(run_dir: Path, metadata: Mapping[str, Any], grid_files: Sequence[str] = ()) -> list[str]:
    """Problems of every file in ``run_dir`` against the metadata's sha256 (empty: all match).

    Every recorded file must be there with its sha256, and every other entry of the directory
    (but ``run_metadata.json`` and ``grid_files``) is named as extra.
    """
    run_dir = Path(run_dir)
    path = run_dir / METADATA_FILE
    problems = [] if metadata.get("complete") is True else [f"{path} does not mark the run complete"]
    skipped = {METADATA_FILE, *grid_files}
    # The report's folder (``solarchain-eval report RUN``) is derived from the vouched files.
    entries = sorted(p for p in run_dir.iterdir() if p.name not in skipped and not _is_report_dir(p))
    problems += verify_files(run_dir, metadata.get("files"), path, [p.name for p in entries if p.is_file()])
    problems += [f"{p} is not a file and is not vouched for by {METADATA_FILE}" for p in entries if not p.is_file()]
    return problems


def _is_report_dir(path: Path) -> bool:
    return path.name == REPORT_DIR and path.is_dir()


def check_protocol(metadata: Mapping[str, Any], config: BenchmarkConfig) -> list[str]:
    """Where the recorded fingerprint disagrees with its id or with the rest of the metadata."""
    recorded = metadata.get("protocol")
    if not isinstance(recorded, dict):
        return ["run_metadata.json records no protocol fingerprint (written by an older version?)"]
    problems = []
    if protocol_id(recorded) != metadata.get("protocol_id"):
        problems.append(f"protocol_id {metadata.get('protocol_id')!r} is not the id of the recorded fingerprint")
    expected = protocol_fingerprint(
        dataset_sha256=(metadata.get("dataset") or {}).get("files") or {},
        run_seeds=metadata.get("run_seeds") or [],
        episodes=int(metadata.get("episodes") or 0),
        episode_seed_rule=str(recorded.get("episode_seed_rule")),
        setting=str(metadata.get("setting")),
        config=config,
        action_modes=recorded.get("action_modes") or {},
    )
    for key in sorted(set(expected) | set(recorded)):
        if expected.get(key) != recorded.get(key):
            problems.append(
                f"fingerprint field {key!r} is {recorded.get(key)!r}; this version and the metadata give {expected.get(key)!r}"
            )
    return problems


def dataset_problem(data_dir: Path, recorded: Mapping[str, str]) -> str | None:
    """Why ``data_dir`` is not the recorded dataset (None: the same CSVs, each with the recorded sha256)."""
    try:
        found = dataset_provenance(load_table(data_dir))["files"]
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


def resolve_dataset(metadata: Mapping[str, Any], data_dir: Path | None) -> tuple[Path | None, str]:
    """The dataset to re-run on and, when there is none, why.

    ``data_dir`` (when given) must hold the recorded CSVs (a :class:`VerifyError` otherwise);
    else the recorded ``data_dir`` is used if its CSVs still have the recorded sha256.
    """
    dataset = metadata.get("dataset") or {}
    recorded = dataset.get("files") or {}
    if not recorded:
        return None, "the run records no dataset sha256"
    if data_dir is not None:
        problem = dataset_problem(data_dir, recorded)
        if problem is not None:
            raise VerifyError.about(
                "{opt_data_dir} {path} is not the run's dataset: {problem}", path=data_dir, problem=problem
            )
        return Path(data_dir), ""
    recorded_dir = Path(str(dataset.get("data_dir", "")))
    problem = dataset_problem(recorded_dir, recorded) if recorded_dir.is_dir() else f"{recorded_dir} is missing"
    if problem is not None:
        return None, f"dataset: {problem}; pass --data DIR with the recorded CSVs"
    return recorded_dir, ""


def read_recorded_rows(path: Path) -> dict[tuple[str, int, int], dict[str, str]]:
    """``metrics.csv`` rows as written (cell text), by (policy, run seed, episode)."""
    with open(path, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    return {(r["policy"], int(r["run_seed"]), int(r["episode"])): r for r in rows}


def written_row(result: EpisodeResult) -> dict[str, str]:
    """The re-run episode's ``metrics.csv`` row as the run's CSV writer writes it (cell text)."""
    text = metrics_frame([result]).to_csv()
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
