"""Writing a run directory so that it is one whole run or nothing (see docs/output_safety.md).

:class:`RunDirWriter` guards ``RUN_DIR`` for one writer:

- **refusal**: an ``RUN_DIR`` that is a file, sits in an unwritable folder, or already holds
  anything (a finished run, a partial one, unrelated files) is refused before any work, unless
  ``overwrite`` is given, in which case the old directory is replaced as a whole;
- **lock**: ``.RUN_DIR.lock`` beside it is held with ``flock`` for the writer's lifetime. The
  kernel drops the lock when the writer dies, so a dead writer's lock never blocks (and a reused
  pid cannot keep it alive); the file records the writer's pid and start time for the message;
- **staging and publication**: outputs are written into a sibling ``.RUN_DIR.staging-*`` folder
  and published by renaming the whole folder. Replacing a run renames the old one aside first
  (``.RUN_DIR.old-*``), so a kill at any moment leaves the previous run, the new run, or no
  run at ``RUN_DIR`` -- never a mix. Orphaned staging and old folders of killed writers are
  removed by the next writer (under the lock).
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import shutil
import signal
import tempfile
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

from ..common.atomic_files import sha256_file
from ..common.errors import NamesOptions, OptionsError
from .records import (
    ACTIONS_FILE,
    ACTIONS_PARQUET,
    AGENTIC_LOG_FILE,
    CITY_HOUR_FILE,
    CITY_HOUR_PARQUET,
    DIAGNOSTICS_FILE,
    METADATA_FILE,
    METRICS_FILE,
    SUMMARY_FILE,
)
from .run_metadata import RunMetadata, RunMetadataError

#: The files a run directory's metadata vouches for, when present.
RUN_FILES = (
    METRICS_FILE,
    ACTIONS_FILE,
    CITY_HOUR_FILE,
    ACTIONS_PARQUET,
    CITY_HOUR_PARQUET,
    AGENTIC_LOG_FILE,
    DIAGNOSTICS_FILE,
    SUMMARY_FILE,
)
#: Environment variable naming a point where the writer kills itself with SIGKILL (kill tests).
KILL_AT_ENV = "SOLARCHAIN_TEST_KILL_AT"
KILL_POINTS = ("staged", "metadata", "old-moved", "published")


class RunDirError(NamesOptions, OptionsError, ValueError):
    """The run directory cannot be written (a one-line message naming it and why)."""


def kill_point(name: str) -> None:
    """SIGKILL this process at ``name`` when :data:`KILL_AT_ENV` asks (crash-safety tests only)."""
    if os.environ.get(KILL_AT_ENV) == name:
        os.kill(os.getpid(), signal.SIGKILL)


def lock_path(run_dir: Path) -> Path:
    return run_dir.parent / f".{run_dir.name}.lock"


def _describe(run_dir: Path, keep: Sequence[str]) -> str | None:
    """What ``run_dir`` holds besides ``keep`` (None when absent or empty)."""
    if not run_dir.is_dir():
        return None
    names = sorted(p.name for p in run_dir.iterdir() if p.name not in keep)
    if not names:
        return None
    metadata = run_dir / METADATA_FILE
    if metadata.is_file():
        try:
            complete = RunMetadata.read(metadata).complete
        except RunMetadataError:
            complete = False
        if complete:
            return "a finished run"
    if any(n.endswith((".csv", ".json", ".jsonl", ".parquet", ".partial")) for n in names):
        return f"a partial run ({', '.join(names[:3])}{', …' if len(names) > 3 else ''})"
    return f"unrelated files ({', '.join(names[:3])}{', …' if len(names) > 3 else ''})"


def check_target(run_dir: Path, *, overwrite: bool = False, keep: Sequence[str] = ()) -> None:
    """Refuse ``run_dir`` if it is a file, cannot be created, or holds anything (unless ``overwrite``).

    Raises
    ------
    RunDirError
        With a one-line message naming ``run_dir``.
    """
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise RunDirError.about("{opt_run_dir} {run_dir} is an existing file, not a run directory", run_dir=run_dir)
    ancestor = run_dir.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise RunDirError.about(
            "{opt_run_dir} {run_dir}: {ancestor} is a file, not a folder", run_dir=run_dir, ancestor=ancestor
        )
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise RunDirError.about(
            "{opt_run_dir} {run_dir}: the folder {ancestor} is not writable", run_dir=run_dir, ancestor=ancestor
        )
    held = _describe(run_dir, keep)
    if held is not None and not overwrite:
        raise RunDirError.about(
            "{opt_run_dir} {run_dir} already holds {held}; choose another {opt_run_dir} or pass {opt_overwrite} "
            "to replace it",
            run_dir=run_dir,
            held=held,
        )


class RunDirWriter:
    """Context manager: lock ``run_dir``, stage outputs in :attr:`staging`, :meth:`publish` them.

    Leaving the context without :meth:`publish` removes the staging folder and leaves
    ``run_dir`` as it was.

    Parameters
    ----------
    run_dir : Path
        The run directory to write.
    overwrite : bool
        Replace whatever ``run_dir`` holds (the old files are removed, never mixed with the new).
    keep : sequence of str
        Names in ``run_dir`` that belong to the caller (e.g. a grid unit's ``unit.json``): they
        do not count as contents and are carried over into the published directory.
    """

    def __init__(self, run_dir: Path, *, overwrite: bool = False, keep: Sequence[str] = ()) -> None:
        self.run_dir = Path(run_dir).absolute()
        self.overwrite = overwrite
        self.keep = tuple(keep)
        self.staging: Path | None = None
        self._lock_fd: int | None = None
        self._published = False

    # --- context ------------------------------------------------------------------------
    def __enter__(self) -> RunDirWriter:
        check_target(self.run_dir, overwrite=self.overwrite, keep=self.keep)
        try:
            self.run_dir.parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise RunDirError.about(
                "{opt_run_dir} {run_dir}: cannot create {parent} ({why})",
                run_dir=self.run_dir,
                parent=self.run_dir.parent,
                why=error.strerror,
            ) from None
        self._lock()
        try:
            # Re-checked under the lock: another writer may have published since the first check.
            check_target(self.run_dir, overwrite=self.overwrite, keep=self.keep)
            self._remove_orphans()
            try:
                self.staging = Path(tempfile.mkdtemp(prefix=f".{self.run_dir.name}.staging-", dir=self.run_dir.parent))
            except OSError as error:
                raise RunDirError.about(
                    "{opt_run_dir} {run_dir}: cannot write in {parent} ({why})",
                    run_dir=self.run_dir,
                    parent=self.run_dir.parent,
                    why=error.strerror,
                ) from None
            os.chmod(self.staging, 0o777 & ~_umask())  # mkdtemp makes it owner-only
        except BaseException:
            self._unlock()
            raise
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        try:
            if not self._published and self.staging is not None:
                shutil.rmtree(self.staging, ignore_errors=True)
        finally:
            self._unlock()

    # --- publication --------------------------------------------------------------------
    def publish(self) -> Path:
        """Move the staged directory to ``run_dir`` (replacing the old one as a whole)."""
        assert self.staging is not None, "publish() outside the context"
        kill_point("metadata")
        for name in self.keep:
            source = self.run_dir / name
            if source.is_file():
                try:
                    os.link(source, self.staging / name)  # same inode: a writer holding it open keeps writing
                except OSError:
                    shutil.copy2(source, self.staging / name)
        parent = self.run_dir.parent
        old: Path | None = None
        if self.run_dir.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{self.run_dir.name}.old-", dir=parent))
            os.rename(self.run_dir, old / "run")
            kill_point("old-moved")
        os.rename(self.staging, self.run_dir)
        self._published = True
        _fsync_dir(parent)
        kill_point("published")
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return self.run_dir

    # --- internals ----------------------------------------------------------------------
    def _remove_orphans(self) -> None:
        """Staging and old folders of writers that died (safe: we hold the lock)."""
        prefix = f".{self.run_dir.name}."
        for path in self.run_dir.parent.glob(f"{_glob_escape(prefix)}*"):
            rest = path.name[len(prefix) :]
            if path.is_dir() and (rest.startswith(("staging-", "old-"))):
                shutil.rmtree(path, ignore_errors=True)
        if self.run_dir.is_dir():
            for path in self.run_dir.glob("*.partial"):
                path.unlink(missing_ok=True)

    def _lock(self) -> None:
        path = lock_path(self.run_dir)
        while True:
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666 & ~_umask())
            except OSError as error:
                raise RunDirError.about(
                    "{opt_run_dir} {run_dir}: cannot create the lock file {path} ({why})",
                    run_dir=self.run_dir,
                    path=path,
                    why=error.strerror,
                ) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as error:
                os.close(fd)
                if error.errno not in (errno.EWOULDBLOCK, errno.EACCES):
                    raise
                raise RunDirError.about(
                    "{opt_run_dir} {run_dir} is being written by another run ({holder}); wait for it to finish",
                    run_dir=self.run_dir,
                    holder=_holder(path),
                ) from None
            try:
                same = os.fstat(fd).st_ino == os.stat(path).st_ino
            except FileNotFoundError:
                same = False
            if same:  # else the previous holder removed the file after we opened it: retry
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, json.dumps({"pid": os.getpid(), "started": _process_start(os.getpid())}).encode())
        self._lock_fd = fd

    def _unlock(self) -> None:
        if self._lock_fd is None:
            return
        lock_path(self.run_dir).unlink(missing_ok=True)  # before unlocking, so no one locks a removed file
        os.close(self._lock_fd)
        self._lock_fd = None


def _holder(path: Path) -> str:
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
        return f"pid {int(info['pid'])}"
    except (OSError, ValueError, KeyError, TypeError):
        return "pid unknown"


def _process_start(pid: int) -> int | None:
    """The process's start time in clock ticks since boot (Linux), to tell a reused pid apart."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        return int(stat.rsplit(")", 1)[1].split()[19])
    except (OSError, ValueError, IndexError):
        return None


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _glob_escape(text: str) -> str:
    return "".join(f"[{c}]" if c in "*?[" else c for c in text)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def verify_files(folder: Path, recorded: object, vouched_by: Path, names: Sequence[str] = RUN_FILES) -> list[str]:
    """Problems of ``folder``'s files against ``recorded`` ({name: sha256}) from ``vouched_by``.

    Every recorded file must exist with that sha256, and every file of ``names`` present in
    ``folder`` must be recorded (else it was left by another run).
    """
    if not isinstance(recorded, dict) or not recorded:
        return [f"{vouched_by} records no sha256 of the files it vouches for (written by an older version?)"]
    problems = []
    for name, digest in sorted(recorded.items()):
        path = folder / str(name)
        if not path.is_file():
            problems.append(f"{path} is listed in {vouched_by.name} but missing")
        elif sha256_file(path) != digest:
            problems.append(f"{path} does not match the sha256 in {vouched_by.name} (changed, or from another run)")
    for name in names:
        if name not in recorded and (folder / name).is_file():
            problems.append(f"{folder / name} is not vouched for by {vouched_by.name} (left over from another run)")
    return problems


def verify_run_dir(run_dir: Path) -> list[str]:
    """Why ``run_dir``'s files cannot be trusted as one run (empty when they can)."""
    run_dir = Path(run_dir)
    path = run_dir / METADATA_FILE
    if not path.is_file():
        return [f"{run_dir} has no {METADATA_FILE}: nothing vouches that its files are one complete run"]
    try:
        metadata = RunMetadata.read(path)
    except RunMetadataError as error:
        return [str(error)]
    if not metadata.complete:
        return [f"{path} does not mark the run complete"]
    return verify_files(run_dir, metadata.files, path)
