"""Provenance of a dataset directory: its path and the sha256 of its files, as run metadata records it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common.atomic_files import sha256_file
from .files import DATASET_FILES, MANIFEST_FILE
from .table import HourlyTable


def dataset_provenance(table: HourlyTable) -> dict[str, Any]:
    """``data_dir`` (resolved), ``files`` (name -> sha256 of each dataset CSV present) and
    ``manifest_sha256`` when the directory has a manifest."""
    root = Path(table.source)
    info: dict[str, Any] = {"data_dir": str(root.resolve()), "files": {}}
    for name in DATASET_FILES:
        path = root / name
        if path.is_file():
            info["files"][name] = sha256_file(path)
    manifest = root / MANIFEST_FILE
    if manifest.is_file():
        info["manifest_sha256"] = sha256_file(manifest)
    return info
