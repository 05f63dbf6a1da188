"""Evaluation records written as the episodes finish, so memory stays flat in their number.

:class:`RecordStream` holds a finished episode (:meth:`~RecordStream.add`) only until
:data:`FLUSH_STEPS` steps have gathered. Then their per-step rows are appended to the step tables
(``actions`` and ``city_hour_policy``: CSV, or Parquet with ``step_format="parquet"``), the
agentic log and the diagnostics, and their metrics rows join a compact frame (a few hundred bytes
an episode). :meth:`~RecordStream.finish` writes ``metrics.csv`` and ``summary.json`` and moves
every file into place. The CSV files are those :func:`~.records.write_records` writes from all
the episodes at once, byte for byte (tests/test_record_stream.py).

:func:`check_disk_space` refuses, before any work, a run whose files would not fit on the disk.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from ..common.atomic_files import AtomicFile, atomic_write_csv, atomic_write_json
from ..tasks.base import Task
from .records import (
    ACTIONS_FILE,
    ACTIONS_PARQUET,
    AGENTIC_LOG_FILE,
    CITY_HOUR_FILE,
    CITY_HOUR_PARQUET,
    DIAGNOSTICS_FILE,
    METRICS_FILE,
    SUMMARY_FILE,
    actions_frame,
    agentic_log_text,
    city_hour_frame,
    diagnostics_csv,
    metrics_frame,
    summarize,
)
from .rollout import EpisodeResult
from .rundir import RunDirError

#: Steps gathered before they are written: a few MB of rows, and few enough writes to be cheap.
FLUSH_STEPS = 20_000
#: ``--step-format``: the files of the two per-step tables.
STEP_FORMATS = {"csv": (ACTIONS_FILE, CITY_HOUR_FILE), "parquet": (ACTIONS_PARQUET, CITY_HOUR_PARQUET)}
#: Bytes a row takes on disk, measured on the default dataset (5 cities) with the three
#: baselines, 2,700 episodes: 386 / 108 / 236 bytes in CSV, 59 / 5 bytes in Parquet; with a
#: margin. :func:`estimate_bytes` adds :data:`FIXED_BYTES` (headers, summary, metadata).
ACTION_ROW_BYTES = {"csv": 420, "parquet": 70}
CITY_ROW_BYTES = {"csv": 120, "parquet": 8}
METRICS_ROW_BYTES = 260
FIXED_BYTES = 64_000
#: Room left free beside the estimate (logs, the file system's own needs).
DISK_MARGIN_BYTES = 1 << 30


class RecordStream:
    """The record files of one run, written into ``folder`` as episodes arrive in protocol order.

    Use it as a context manager: leaving it without :meth:`finish` removes the partial files.

    Parameters
    ----------
    folder : Path
        Where the files go (a run directory's staging folder).
    cities : sequence of str
        The names of the task's step extras (the solar market: the dataset's cities), the city-hour
        table's rows per step; none: no city-hour table.
    step_format : str
        A key of :data:`STEP_FORMATS`.
    task : Task, optional
        The market whose records these are (their columns; default: the solar market).
    """

    def __init__(self, folder: Path, cities: Sequence[str], step_format: str = "csv", task: Task | None = None) -> None:
        if step_format not in STEP_FORMATS:
            raise ValueError(f"step format must be one of {', '.join(STEP_FORMATS)}, got {step_format!r}")
        self.folder = Path(folder)
        self.cities = tuple(cities)
        self.step_format = step_format
        self.task = task
        self.episodes = 0
        self.steps = 0
        #: The summary :meth:`finish` wrote (``summary.json``).
        self.summary: list[dict[str, Any]] = []
        self._pending: list[EpisodeResult] = []
        self._pending_steps = 0
        self._metrics: list[pd.DataFrame] = []
        self._files: dict[str, AtomicFile] = {}
        self._parquet: dict[str, Any] = {}

    def __enter__(self) -> RecordStream:
        return self

    def __exit__(self, *exc: object) -> None:
        for writer in self._parquet.values():
            writer.close()
        for file in self._files.values():
            if not file.handle.closed:
                file.discard()

    def add(self, result: EpisodeResult) -> None:
        """Take a finished episode (the next in protocol order)."""
        self._pending.append(result)
        self._pending_steps += result.n_steps
        self.episodes += 1
        self.steps += result.n_steps
        if self._pending_steps >= FLUSH_STEPS:
            self.flush()

    def flush(self) -> None:
        """Write the episodes taken since the last flush."""
        batch, self._pending, self._pending_steps = self._pending, [], 0
        if not batch:
            return
        self._metrics.append(metrics_frame(batch, self.task))
        actions, city_hour = STEP_FORMATS[self.step_format]
        self._append_table(actions, actions_frame(batch, self.task))
        if self.cities:
            self._append_table(city_hour, city_hour_frame(batch, self.cities, self.task))
        log = agentic_log_text(batch)
        if log is not None:
            self._file(AGENTIC_LOG_FILE).handle.write(log)
        diagnostics = diagnostics_csv(batch, self.task)
        if diagnostics is not None:
            first = DIAGNOSTICS_FILE not in self._files
            self._file(DIAGNOSTICS_FILE).handle.write(diagnostics if first else diagnostics.split("\n", 1)[1])

    def finish(self) -> dict[str, Path]:
        """Write what is left, ``metrics.csv`` and ``summary.json``; move every file into place.

        Returns the files in :func:`~.records.write_records`'s order.
        """
        self.flush()
        actions, city_hour = STEP_FORMATS[self.step_format]
        if actions not in self._files:  # no episode: the tables' headers only, as write_records
            self._append_table(actions, actions_frame([], self.task))
            if self.cities:
                self._append_table(city_hour, city_hour_frame([], self.cities, self.task))
        metrics = _concat_metrics(self._metrics, self.task)
        self._metrics = []
        paths = {METRICS_FILE: atomic_write_csv(self.folder / METRICS_FILE, metrics)}
        for writer in self._parquet.values():
            writer.close()  # the footer; the file stays open for commit()
        self._parquet = {}
        for name in (actions, city_hour, AGENTIC_LOG_FILE, DIAGNOSTICS_FILE):
            if name in self._files:
                paths[name] = self._files[name].commit()
        self.summary = summarize(metrics)
        paths[SUMMARY_FILE] = atomic_write_json(self.folder / SUMMARY_FILE, self.summary)
        return paths

    def _file(self, name: str) -> AtomicFile:
        file = self._files.get(name)
        if file is None:
            file = self._files[name] = AtomicFile(self.folder / name, binary=name.endswith(".parquet"))
        return file

    def _append_table(self, name: str, frame: pd.DataFrame) -> None:
        first = name not in self._files
        handle = self._file(name).handle
        if not name.endswith(".parquet"):
            frame.to_csv(handle, header=first, index=False)
            return
        import pyarrow as pa
        import pyarrow.parquet as pq

        writer = self._parquet.get(name)
        if writer is None:
            table = pa.Table.from_pandas(frame, preserve_index=False)
            writer = self._parquet[name] = pq.ParquetWriter(handle, table.schema)
        else:
            table = pa.Table.from_pandas(frame, schema=writer.schema, preserve_index=False)
        writer.write_table(table)


def _concat_metrics(frames: list[pd.DataFrame], task: Task | None = None) -> pd.DataFrame:
    """The chunks' metrics rows as :func:`~.records.metrics_frame` gives all of them at once: each
    chunk starts with the fixed columns, and a column first seen in a later chunk comes after
    those already there (pandas fills the rows without it with NaN, as the whole frame does)."""
    if not frames:
        return metrics_frame([], task)
    return frames[0] if len(frames) == 1 else pd.concat(frames, ignore_index=True, sort=False)


def estimate_bytes(episodes: int, steps_per_episode: int, cities: int, step_format: str = "csv") -> int:
    """About how many bytes the record files of ``episodes`` episodes take."""
    steps = episodes * steps_per_episode
    per_step = ACTION_ROW_BYTES[step_format] + cities * CITY_ROW_BYTES[step_format]
    return steps * per_step + episodes * METRICS_ROW_BYTES + FIXED_BYTES


def check_disk_space(run_dir: Path, episodes: int, steps_per_episode: int, cities: int, step_format: str) -> int:
    """Refuse (:class:`~.rundir.RunDirError`) a run whose files would not fit beside ``run_dir``.

    Returns the estimate in bytes.
    """
    estimate = estimate_bytes(episodes, steps_per_episode, cities, step_format)
    folder = Path(run_dir).absolute().parent
    while not folder.exists():
        folder = folder.parent
    free = shutil.disk_usage(folder).free
    if estimate + DISK_MARGIN_BYTES > free:
        raise RunDirError.about(
            "{opt_run_dir} {run_dir}: {episodes:,} episodes of {steps} steps would write about {size} of records "
            "and {folder} has {free} free; evaluate fewer episodes, run seeds or policies, or write elsewhere",
            run_dir=run_dir,
            episodes=episodes,
            steps=steps_per_episode,
            size=format_bytes(estimate),
            folder=folder,
            free=format_bytes(free),
        )
    return estimate


def format_bytes(count: float) -> str:
    """``2.1 GB`` (decimal units, as ``df -H``)."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if count < 1000 or unit == "PB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.1f} {unit}"
        count /= 1000
    raise AssertionError("unreachable")
