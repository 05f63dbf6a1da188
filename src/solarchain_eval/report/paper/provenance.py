"""Dataset provenance and run metadata for the report, from run_metadata.json / paper_metadata.json."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ...common.atomic_files import sha256_file
from ...tasks.base import dataset_manifest_of
from ..loading import ReportData

#: Run-metadata fields the report shows in its summary table (the rest is in the JSON dump).
RUN_FIELDS = (
    "command",
    "started_at",
    "wall_s",
    "git_commit",
    "setting",
    "policies",
    "policy_access",  # isolated, in-process or privileged, per policy
    "run_seeds",
    "episodes",
    "episode_seed_protocol",
    "rows",
)


def _datasets_in(metadata: dict[str, Any]) -> list[dict[str, Any]]:
    dataset = metadata.get("dataset")
    if isinstance(dataset, dict):
        return [dataset]
    if isinstance(dataset, list):
        return [d for d in dataset if isinstance(d, dict)]
    return []


def file_status(data_dir: Path, name: str, recorded: str) -> str:
    """Whether ``data_dir/name`` still has the recorded sha256: "matches", "differs" or "missing"."""
    path = data_dir / name
    if not path.is_file():
        return "missing"
    return "matches" if sha256_file(path) == recorded else "differs"


def dataset_records(data: ReportData) -> list[dict[str, Any]]:
    """Each distinct dataset the run used: directory, files with sha256 and whether they still match,
    the manifest's sha256 and content (when the directory has one), and the units that used it.
    """
    sources = [("run" if data.kind == "run" else "paper", data.metadata)]
    sources += [(name, meta) for name, meta in data.unit_metadata.items()]
    records: dict[str, dict[str, Any]] = {}
    for source, metadata in sources:
        for dataset in _datasets_in(metadata):
            files = dict(sorted((dataset.get("files") or {}).items()))
            key = json.dumps([dataset.get("data_dir"), files], sort_keys=True)
            if key not in records:
                data_dir = Path(str(dataset.get("data_dir", "")))
                manifest_name = dataset_manifest_of(data.task_spec)
                manifest_path = data_dir / manifest_name if manifest_name else None
                manifest = None
                if manifest_path is not None and manifest_path.is_file():
                    try:
                        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
                    except json.JSONDecodeError:
                        manifest = {"error": f"{manifest_path} is not valid JSON"}
                records[key] = {
                    "data_dir": str(dataset.get("data_dir", "unknown")),
                    "files": [
                        {"name": name, "sha256": digest, "status": file_status(data_dir, name, digest)}
                        for name, digest in files.items()
                    ],
                    "manifest_sha256": dataset.get("manifest_sha256"),
                    "manifest": manifest,
                    "used_by": [],
                }
            records[key]["used_by"].append(source)
    return list(records.values())


def run_records(data: ReportData) -> list[dict[str, Any]]:
    """The summary fields of the run's metadata (one record per evaluation unit of a paper root)."""
    if data.kind == "run":
        return (
            [{"unit": data.root.name, **{k: data.metadata[k] for k in RUN_FIELDS if k in data.metadata}}]
            if data.metadata
            else []
        )
    return [
        {"unit": name, **{k: meta[k] for k in RUN_FIELDS if k in meta}} for name, meta in data.unit_metadata.items()
    ]
