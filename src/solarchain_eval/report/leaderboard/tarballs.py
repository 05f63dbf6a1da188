"""Reading a submitted tarball without trusting it: limits and vouching checked before anything
is written (docs/security.md#tarballs).

:func:`unpack_tarball` reads the archive's member list first and refuses it, writing nothing,
when it holds more than ``max_members`` members, more than ``max_unpacked_mb`` of file data,
a member that is neither a file nor a folder (a link, a device), or a file that no metadata in
it vouches for. Vouched for are, in a run directory, ``run_metadata.json`` and the files whose
sha256 it records; in a paper root, ``paper_metadata.json``, the combined files whose sha256 it
records, and each evaluation unit's ``run_metadata.json``, the files it records and the grid's
own bookkeeping (``unit.json``, ``unit.log``, ``DONE``); in a suite root, ``suite_metadata.json``,
the files whose sha256 it records (each entry's ``run_metadata.json`` among them) and the files
each of those run metadata records. The metadata is read from the archive in memory. Only then
are the members extracted (with tarfile's ``data`` filter), and the leaderboard verifies every
file against its sha256 as for a folder.
"""

from __future__ import annotations

import json
import tarfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from ...common.errors import RefusedError
from ...evaluation.run_metadata import RunMetadata, RunMetadataError
from ...evaluation.suite_run import SUITE_METADATA_FILE
from ...experiments.layout import COMBINED_DIR, DONE_MARKER, METADATA_FILE, PAPER_METADATA_FILE, UNITS_DIR
from ..options import DEFAULT_MAX_MEMBERS, DEFAULT_MAX_UNPACKED_MB

#: A metadata file larger than this is not read (no real run's comes near it).
METADATA_MAX_BYTES = 64 * 2**20
#: Files a paper grid keeps in an evaluation unit beside the run's own (``experiments.units``).
UNIT_BOOKKEEPING = ("unit.json", "unit.log", DONE_MARKER)


class TarballRefused(RefusedError, ValueError):
    """A tarball refused before extraction (the one-line message names it and why)."""


@dataclass(frozen=True)
class TarballLimits:
    """What a tarball may unpack to: ``max_unpacked_mb`` MiB of file data in ``max_members`` members."""

    max_unpacked_mb: float = DEFAULT_MAX_UNPACKED_MB
    max_members: int = DEFAULT_MAX_MEMBERS

    def __post_init__(self) -> None:
        if not self.max_unpacked_mb > 0:
            raise ValueError(f"max_unpacked_mb must be positive, got {self.max_unpacked_mb}")
        if self.max_members < 1:
            raise ValueError(f"max_members must be at least 1, got {self.max_members}")


def _members(archive: tarfile.TarFile, tarball: Path, limits: TarballLimits) -> list[tarfile.TarInfo]:
    """The archive's members, refused as soon as one passes a limit (the file data is not read)."""
    members: list[tarfile.TarInfo] = []
    total = 0
    limit = limits.max_unpacked_mb * 2**20
    for member in archive:
        members.append(member)
        total += member.size if member.isfile() else 0
        if len(members) > limits.max_members:
            raise TarballRefused(
                f"{tarball}: holds more than {limits.max_members} members; refused before unpacking "
                "(raise the limit with --max-members if the run really has that many files)"
            )
        if total > limit:
            raise TarballRefused(
                f"{tarball}: unpacks to more than {limits.max_unpacked_mb:g} MB ({member.name} alone is "
                f"{member.size / 2**20:.1f} MB); refused before unpacking (raise the limit with --max-unpacked-mb)"
            )
        if not (member.isfile() or member.isdir()):
            raise TarballRefused(f"{tarball}: {member.name} is a link or special file; a run holds only files")
        path = PurePosixPath(member.name)
        if path.is_absolute() or ".." in path.parts:
            raise TarballRefused(f"{tarball}: {member.name} points outside the archive's folder")
    return members


def _top(names: list[PurePosixPath]) -> PurePosixPath:
    """The folder every member lies in (a tarball of ``RUN_DIR``), or the archive's root."""
    tops = {name.parts[0] for name in names if name.parts}
    if len(tops) == 1 and any(len(name.parts) > 1 for name in names):
        return PurePosixPath(next(iter(tops)))
    return PurePosixPath()


def _run_files(read_json: Callable[[str], Any], path: str) -> list[str] | None:
    """The files a ``run_metadata.json`` in the archive vouches for (None: there is none).

    Raises
    ------
    RunMetadataError
        It is malformed (the message names it and the field).
    """
    data = read_json(path)
    return None if data is None else list(RunMetadata.from_record(data, path).files or {})


def vouched_files(read_json: Callable[[str], Any], folders: set[str]) -> set[str]:
    """Paths (relative to the run or paper root, ``/``-separated) that its metadata vouches for.

    ``read_json(path)`` gives a metadata file's JSON (None when absent); ``folders`` are the
    folders the archive holds (to find a paper root's evaluation units).
    """
    suite = read_json(SUITE_METADATA_FILE)
    if suite is not None:
        return _suite_files(read_json, suite)
    paper = read_json(PAPER_METADATA_FILE)
    if paper is None:
        return {METADATA_FILE, *(_run_files(read_json, METADATA_FILE) or [])}
    vouched = {PAPER_METADATA_FILE}
    combined = paper.get("combined_sha256") if isinstance(paper, dict) else None
    for setting, files in (combined or {}).items() if isinstance(combined, dict) else ():
        if isinstance(files, dict):
            vouched |= {f"{COMBINED_DIR}/{setting}/{name}" for name in files}
    prefix = f"{UNITS_DIR}/eval/"
    for folder in sorted(f for f in folders if f.startswith(prefix) and "/" not in f[len(prefix) :]):
        unit = _run_files(read_json, f"{folder}/{METADATA_FILE}")
        if unit is not None:
            names = [METADATA_FILE, *unit, *UNIT_BOOKKEEPING]
            vouched |= {f"{folder}/{name}" for name in names}
    return vouched


def _suite_files(read_json: Callable[[str], Any], suite: Any) -> set[str]:
    """What a suite root's ``suite_metadata.json`` vouches for: itself, the files whose sha256 it
    records and, for each entry's ``run_metadata.json`` among them, the files that one records."""
    vouched = {SUITE_METADATA_FILE}
    recorded = suite.get("sha256") if isinstance(suite, dict) else None
    for path in recorded if isinstance(recorded, dict) else ():
        if not isinstance(path, str):
            continue
        vouched.add(path)
        folder, _, name = path.rpartition("/")
        if folder and name == METADATA_FILE:
            vouched |= {f"{folder}/{file}" for file in _run_files(read_json, path) or []}
    return vouched


def unpack_tarball(tarball: Path, into: Path, limits: TarballLimits | None = None) -> Path:
    """Check ``tarball`` (module docstring), extract it into ``into`` and return the run or root inside.

    Raises
    ------
    TarballRefused
        Not a readable tarball, past a limit, or holding a link or a file nothing vouches for;
        nothing has been written then.
    """
    limits = limits or TarballLimits()
    try:
        with tarfile.open(tarball) as archive:
            members = _members(archive, tarball, limits)
            names = {m.name: PurePosixPath(m.name) for m in members if PurePosixPath(m.name).parts}
            top = _top(list(names.values()))
            relative = {name: path.relative_to(top).as_posix() for name, path in names.items() if path != top}
            files = {rel: name for name, rel in relative.items() if archive.getmember(name).isfile()}

            def read_json(path: str) -> Any:
                name = files.get(path)
                if name is None:
                    return None
                member = archive.getmember(name)
                if member.size > METADATA_MAX_BYTES:
                    raise TarballRefused(
                        f"{tarball}: {name} is {member.size / 2**20:.0f} MB; no metadata is that large"
                    )
                handle = archive.extractfile(member)
                try:
                    return json.loads(handle.read()) if handle is not None else None
                except ValueError:
                    raise TarballRefused(f"{tarball}: {name} is not valid JSON") from None

            folders = {rel for name, rel in relative.items() if archive.getmember(name).isdir()}
            folders |= {str(PurePosixPath(rel).parent) for rel in files}
            if all(read_json(name) is None for name in (METADATA_FILE, PAPER_METADATA_FILE, SUITE_METADATA_FILE)):
                raise TarballRefused(
                    f"{tarball}: holds no {METADATA_FILE}, {PAPER_METADATA_FILE} or {SUITE_METADATA_FILE} at its top "
                    "or in its one folder; pack one run directory, paper root or suite root (tar czf run.tar.gz RUN_DIR)"
                )
            try:
                vouched = vouched_files(read_json, folders)
            except RunMetadataError as error:
                raise TarballRefused(f"{tarball}: {error}") from None
            stray = sorted(rel for rel in files if rel not in vouched)
            if stray:
                more = f" (and {len(stray) - 1} more)" if len(stray) > 1 else ""
                if SUITE_METADATA_FILE in files:
                    pack = "pack only the suite root (tar czf suite.tar.gz SUITE_ROOT)"
                elif PAPER_METADATA_FILE in files:
                    pack = f"pack a paper root's {PAPER_METADATA_FILE}, {COMBINED_DIR}/ and {UNITS_DIR}/eval/ only"
                else:
                    pack = "pack only the run directory (tar czf run.tar.gz RUN_DIR)"
                raise TarballRefused(
                    f"{tarball}: {top / stray[0]}{more} is not vouched for by the run's metadata; refused before "
                    f"unpacking ({pack})"
                )
            archive.extractall(into, members=members, filter="data")
    except (tarfile.TarError, OSError, EOFError) as error:
        raise TarballRefused(f"{tarball}: not a readable tarball ({error})") from None
    return Path(into) / top
