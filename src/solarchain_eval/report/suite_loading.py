"""Read a suite root (``evaluate --suite``, docs/suites.md) for the report and the leaderboard, verified.

:func:`load_suite_data` trusts nothing it has not checked: ``suite_metadata.json``'s sha256 of
every file it lists, each entry's run as the report reads a run (every file against its run's
metadata), each entry's protocol id against its run's, the suite protocol id against the fields
it hashes, and ``suite_scores.csv`` against the scores recomputed from the entries' runs
(:func:`~solarchain_eval.evaluation.suite_run.entry_scores`). The aggregates are not read: the
report and the board compute them again with
:func:`~solarchain_eval.evaluation.suite_stats.aggregate_table`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..common.atomic_files import read_csv_exact, sha256_file
from ..evaluation.fingerprint import protocol_id
from ..evaluation.suite_run import (
    PROFILE_FILE,
    SUITE_METADATA_FILE,
    SUITE_SCORES_FILE,
    SuiteScoreError,
    entry_scores,
    matrices,
)
from ..evaluation.suite_stats import BOOTSTRAP_SEED
from ..tasks.suites import Suite, SuiteEntry
from .loading import ReportData, load_report_data
from .options import ReportDataError
from .table_files import read_json

#: Fields of ``suite_metadata.json`` a suite root must hold, with their JSON types.
REQUIRED_FIELDS = {
    "suite": str,
    "protocol_id": str,
    "protocol": dict,
    "reference": list,
    "entries": list,
    "sha256": dict,
}


def is_suite_root(path: Path | str) -> bool:
    """Whether ``path`` is a finished suite root (a folder holding ``suite_metadata.json``)."""
    return (Path(path) / SUITE_METADATA_FILE).is_file()


@dataclass
class SuiteData:
    """A verified suite root.

    Attributes
    ----------
    root : Path
    suite : str
    protocol_id : str
        The suite protocol's id (equal ids: comparable suite results).
    protocol : dict
        What it hashes: the entries' run protocol ids, the score, the normalisation, the splits.
    splits : tuple of str
    reference : tuple of (str, str)
        The baselines normalised scores 0 and 1 stand for.
    setting : str
        The setting every entry's run was evaluated in.
    entries : list of dict
        ``name``, ``task``, ``split`` and ``protocol_id`` of each entry, in the suite's order.
    scores : pandas.DataFrame
        ``suite_scores.csv``: one row per entry, policy and episode (``normalised`` among them).
    runs : dict
        Entry name -> its run as the report reads it (:class:`~.loading.ReportData`).
    bootstrap_seed : int
        The seed of the suite's bootstrap intervals (``suite_metadata.json``), reused so that the
        report's and the board's intervals equal those ``evaluate`` printed for the same resamples.
    metadata : dict
        ``suite_metadata.json`` as read.
    """

    root: Path
    suite: str
    protocol_id: str
    protocol: dict[str, Any]
    splits: tuple[str, ...]
    reference: tuple[str, str]
    setting: str
    entries: list[dict[str, Any]]
    scores: pd.DataFrame
    runs: dict[str, ReportData] = field(repr=False)
    bootstrap_seed: int = BOOTSTRAP_SEED
    metadata: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def access(self) -> dict[str, str]:
        """Policy -> how it ran (isolated, in-process, privileged), from its entries' runs."""
        access: dict[str, str] = {}
        for run in self.runs.values():
            if run.run_metadata is not None:
                access.update(run.run_metadata.policy_access)
        return access

    def matrices(self) -> dict[str, np.ndarray]:
        """Policy -> its normalised score matrix (one row per episode, one column per entry)."""
        return matrices(self.scores)


def _field(metadata: dict[str, Any], name: str, kind: type, path: Path) -> Any:
    value = metadata.get(name)
    if not isinstance(value, kind):
        raise ReportDataError(f"{path}: field {name!r} is missing or not a {kind.__name__}")
    return value


def _check_sha256(root: Path, recorded: dict[str, Any], path: Path) -> None:
    for name in (SUITE_SCORES_FILE, PROFILE_FILE):
        if name not in recorded:
            raise ReportDataError(f"{path}: field 'sha256' does not vouch for {name}")
    for name, digest in recorded.items():
        target = root / name
        if not target.is_file():
            raise ReportDataError(f"{target}: missing (listed in {path})")
        if sha256_file(target) != digest:
            raise ReportDataError(f"{target}: its sha256 differs from the one {path} records (edited?)")


def _recomputed(suite: Suite, runs: dict[str, ReportData], scores: pd.DataFrame, path: Path) -> None:
    """``suite_scores.csv`` equals the scores recomputed from the entries' verified runs, row for row."""
    fresh = pd.concat([entry_scores(e, runs[e.name].metrics, suite) for e in suite.entries], ignore_index=True)
    key = ["entry", "policy", "run_seed", "episode"]
    if list(scores.columns) != list(fresh.columns) or len(scores) != len(fresh):
        raise ReportDataError(f"{path}: its rows or columns differ from the scores of the entries' runs")
    a, b = scores.sort_values(key).reset_index(drop=True), fresh.sort_values(key).reset_index(drop=True)
    same_keys = a[[*key, "split"]].astype(str).equals(b[[*key, "split"]].astype(str))
    close = np.allclose(a[["score", "normalised"]].to_numpy(float), b[["score", "normalised"]].to_numpy(float))
    if not (same_keys and close):
        raise ReportDataError(f"{path}: its scores differ from those recomputed from the entries' runs (edited?)")


def load_suite_data(root: Path | str, *, read_run: Callable[[Path], ReportData] = load_report_data) -> SuiteData:
    """Read and verify the suite root ``root`` (see the module docstring).

    ``read_run`` reads each entry's run directory (default :func:`~.loading.load_report_data`,
    which verifies every file against the run's metadata).

    Raises
    ------
    ReportDataError
        A file is missing, unreadable or not vouched for, or a recorded id or score disagrees with
        what it records (one line naming the file and field).
    """
    root = Path(root)
    path = root / SUITE_METADATA_FILE
    if not path.is_file():
        raise ReportDataError(f"{root}: no {SUITE_METADATA_FILE} (not a suite root, or an unfinished one)")
    metadata = read_json(path)
    for name, kind in REQUIRED_FIELDS.items():
        _field(metadata, name, kind, path)
    entries, reference = metadata["entries"], tuple(metadata["reference"])
    if len(reference) != 2:
        raise ReportDataError(f"{path}: field 'reference' must name two baselines")
    _check_sha256(root, metadata["sha256"], path)
    protocol = metadata["protocol"]
    if protocol_id(protocol) != metadata["protocol_id"]:
        raise ReportDataError(f"{path}: field 'protocol' does not hash to its protocol_id (edited by hand?)")
    runs: dict[str, ReportData] = {}
    for entry in entries:
        if not isinstance(entry, dict) or not {"name", "task", "split", "protocol_id"} <= set(entry):
            raise ReportDataError(f"{path}: field 'entries' holds an entry without name, task, split and protocol_id")
        run = read_run(root / str(entry.get("run_dir", entry["name"])))
        recorded = run.run_metadata.protocol_id if run.run_metadata is not None else None
        if recorded != entry["protocol_id"]:
            raise ReportDataError(
                f"{path}: entry {entry['name']!r} records protocol id {entry['protocol_id']} but its run has {recorded}"
            )
        runs[str(entry["name"])] = run
    if sorted(e["protocol_id"] for e in entries) != protocol.get("protocol_ids"):
        raise ReportDataError(f"{path}: field 'protocol' does not list its entries' protocol ids")
    if sorted({e["split"] for e in entries}) != protocol.get("splits"):
        raise ReportDataError(f"{path}: field 'protocol' does not list its entries' splits")
    settings = sorted({s for run in runs.values() for s in run.metrics["setting"].astype(str)})
    if len(settings) != 1:
        raise ReportDataError(f"{root}: its entries' runs hold settings {', '.join(settings)}; a suite runs one")
    try:
        suite = Suite(
            str(metadata["suite"]),
            str(metadata.get("description", "")),
            # the entries' datasets are not read again: their runs were verified against their sha256s
            tuple(SuiteEntry(str(e["name"]), str(e["task"]), str(e["split"]), root) for e in entries),
            (str(reference[0]), str(reference[1])),
        )
        scores = read_csv_exact(root / SUITE_SCORES_FILE)
        _recomputed(suite, runs, scores, root / SUITE_SCORES_FILE)
        matrices(scores)  # every policy ran the same episodes on every entry
    except (ValueError, KeyError, SuiteScoreError) as error:
        if isinstance(error, ReportDataError):
            raise
        raise ReportDataError(f"{root}: {error}") from None
    bootstrap = metadata.get("bootstrap") or {}
    return SuiteData(
        root=root,
        suite=suite.name,
        protocol_id=str(metadata["protocol_id"]),
        protocol=protocol,
        splits=tuple(protocol["splits"]),
        reference=suite.reference,
        setting=settings[0],
        entries=[{k: e[k] for k in ("name", "task", "split", "protocol_id")} for e in entries],
        scores=scores,
        runs=runs,
        bootstrap_seed=int(bootstrap.get("seed", BOOTSTRAP_SEED)),
        metadata=metadata,
    )
