"""Progress of JAX trainings on the command line (``train`` and ``paper`` with ``--backend jax``).

On a terminal (stderr) a live display keeps one row per running training: steps, recent
episode return, steps/s and ETA, updated after every chunk. Elsewhere (a file, a pipe,
``nohup``) each chunk prints one plain line instead, so a log shows how a long training goes.
"""

from __future__ import annotations

from types import TracebackType

from rich.console import Console
from rich.progress import BarColumn, Progress, TaskID, TextColumn, TimeElapsedColumn
from rich.text import Text

from ..training.jax_progress import ChunkProgress, format_duration
from .common import err_console


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
