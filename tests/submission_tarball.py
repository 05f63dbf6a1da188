"""Pack a run directory or suite root as a submitted tarball, optionally with extra members (tests' helper)."""

from __future__ import annotations

import io
import tarfile
from pathlib import Path


def pack(tarball: Path, run: Path, extra: dict[str, bytes] | None = None) -> Path:
    """``run`` as ``submission/`` in a gzipped ``tarball``, plus ``extra`` files (name -> bytes) inside it."""
    with tarfile.open(tarball, "w:gz") as archive:
        archive.add(run, arcname="submission")
        for name, data in (extra or {}).items():
            info = tarfile.TarInfo(f"submission/{name}")
            info.size = len(data)
            archive.addfile(info, io.BytesIO(data))
    return tarball
