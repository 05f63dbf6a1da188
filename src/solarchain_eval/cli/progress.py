"""Progress on the command line: JAX trainings (``train`` and ``paper`` with ``--backend jax``)
and counted work such as ``evaluate``'s episodes.

On a terminal (stderr) a live display keeps one row per running training: steps, recent
episode return, steps/s and ETA, updated after every chunk. Elsewhere (a file, a pipe,
``nohup``) each chunk prints one plain line instead, so a log shows how a long training goes.
:func:`count_progress` does the same for a count: a live bar with its ETA on a terminal, else a
plain line with the rate and ETA every :data:`PLAIN_EVERY_S` seconds.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import TracebackType

from rich.console import Console
from rich.progress import BarColumn, Progress, TaskID, TextColumn, TimeElapsedColumn
from rich.text import Text

from ..training.jax_progress import ChunkProgress, format_duration
from .common import err_console, progress_bar

#: Seconds between two plain progress lines (a run shorter than this prints none).
PLAIN_EVERY_S = 10.0


def _summary(progress: ChunkProgress) -> str:
    recent = "-" if progress.recent_return is None else f"{progress.recent_return:.2f}"
    return (
        f"{progress.steps_done:,}/{progress.total_steps:,} steps  return {recent}  "
        f"{progress.steps_per_s:,.0f} steps/s  ETA {format_duration(progress.eta_s)}"
    )


class TrainingProgress:
    """A context manager showing :class:`ChunkProgress` reports of one or more trainings.

    Parameters
    ----------
    console : rich Console
        Where to show it (default: stderr). The live display is used when it is a terminal.
    units : int, optional
        Also count finished units out of ``units`` (``paper``), with :meth:`advance_units`.
    """

    def __init__(self, console: Console | None = None, units: int | None = None) -> None:
        self.console = console or err_console
        self.live = self.console.is_terminal
        self._progress = Progress(
            TextColumn("{task.description}", style="bold", markup=False),
            BarColumn(),
            TextColumn("{task.fields[info]}", markup=False),
            TimeElapsedColumn(),
            console=self.console,
            transient=True,
            disable=not self.live,
        )
        self._tasks: dict[str, TaskID] = {}
        self._units_total, self._units_done = units, 0
        self._units = self._progress.add_task("units", total=units, info=f"0/{units}") if units else None

    def __enter__(self) -> TrainingProgress:
        self._progress.__enter__()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self._progress.__exit__(kind, error, trace)

    def start(self, label: str, total_steps: int, info: str = "compiling") -> None:
        """Show ``label``'s row before its first chunk (live display only)."""
        if self.live and label not in self._tasks:
            self._tasks[label] = self._progress.add_task(label, total=total_steps, info=info)

    def update(self, label: str, progress: ChunkProgress) -> None:
        """``label``'s training finished a chunk: a new row state, or a plain line."""
        if not self.live:
            self.console.print(f"{label}: {progress.describe()}", soft_wrap=True)
            return
        if label not in self._tasks:
            self._tasks[label] = self._progress.add_task(label, total=progress.total_steps, info="")
        self._progress.update(
            self._tasks[label], total=progress.total_steps, completed=progress.steps_done, info=_summary(progress)
        )

    def note(self, label: str, text: str) -> None:
        self.console.print(Text.assemble((label, "bold"), f": {text}"), soft_wrap=True)

    def finish(self, label: str) -> None:
        """``label``'s training is over: its row goes."""
        task = self._tasks.pop(label, None)
        if task is not None:
            self._progress.remove_task(task)

    def advance_units(self, count: int = 1) -> None:
        if self._units is not None:
            self._units_done += count
            self._progress.update(
                self._units, completed=self._units_done, info=f"{self._units_done}/{self._units_total}"
            )


def count_line(description: str, done: int, total: int, elapsed_s: float, unit: str) -> str:
    """``evaluating: 1,200/90,000 episodes (1.3%), 600 episodes/s, ETA 2:28``."""
    rate = done / elapsed_s if elapsed_s > 0 else 0.0
    eta = (total - done) / rate if rate > 0 else None
    share = done / total if total else 1.0
    return f"{description}: {done:,}/{total:,} {unit} ({share:.1%}), {rate:,.1f} {unit}/s, ETA {format_duration(eta)}"


@contextmanager
def count_progress(
    description: str,
    total: int,
    *,
    unit: str = "episodes",
    console: Console | None = None,
    every_s: float | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> Iterator[Callable[[int], None]]:
    """Progress of ``total`` items; yields ``advance(n)``.

    On a terminal, a live bar with its ETA; elsewhere a :func:`count_line` at most every
    ``every_s`` seconds (default :data:`PLAIN_EVERY_S`), so a log of a long run shows how far it
    is and how long it will take.
    """
    console = console or err_console
    every_s = PLAIN_EVERY_S if every_s is None else every_s
    if console.is_terminal:
        with progress_bar(description, total) as advance:
            yield advance
        return
    started = last = clock()
    done = 0

    def advance(count: int = 1) -> None:
        nonlocal done, last
        done += count
        now = clock()
        if now - last >= every_s:
            last = now
            console.print(count_line(description, done, total, now - started, unit), soft_wrap=True, highlight=False)

    yield advance
