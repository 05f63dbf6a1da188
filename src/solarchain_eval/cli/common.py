"""Shared CLI helpers: error reporting, progress bars, result tables."""

from __future__ import annotations

import functools
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator, TypeVar

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from ..config import ConfigError
from ..data.errors import DatasetError
from ..data.weather import WeatherError

# Tables stay readable when output goes to a file or CI log (rich would assume 80 columns).
console = Console(width=None if Console().is_terminal else 140)
err_console = Console(stderr=True)

#: Errors caused by the user's input: reported in one line, exit status 2, no traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (DatasetError, WeatherError, ConfigError)
EXIT_USAGE = 2

F = TypeVar("F", bound=Callable)


class CliError(Exception):
    """A problem with the command's arguments or inputs, reported without a traceback."""


def register_user_error(*types: type[BaseException]) -> None:
    """Let other modules (training, LLM client) add their input errors to the list."""
    global USER_ERRORS
    USER_ERRORS = tuple(dict.fromkeys((*USER_ERRORS, *types)))


def reports_errors(func: F) -> F:
    """Turn user errors into a one-line message and exit status 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except (CliError, *USER_ERRORS) as error:
            err_console.print(f"[bold red]error:[/bold red] {error}", highlight=False, soft_wrap=True)
            raise typer.Exit(EXIT_USAGE) from None
        except KeyboardInterrupt:
            err_console.print("[yellow]interrupted[/yellow]: no partial output file was left behind")
            raise typer.Exit(130) from None

    return wrapper  # type: ignore[return-value]


@contextmanager
def progress_bar(description: str, total: int, *, enabled: bool = True) -> Iterator[Callable[[int], None]]:
    """A rich progress bar; yields ``advance(n)``. Hidden when stderr is not a terminal."""
    if not enabled:
        yield lambda n=1: None
        return
    progress = Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        transient=True,
        disable=not err_console.is_terminal,
    )
    with progress:
        task = progress.add_task(description, total=total)
        yield lambda n=1: progress.advance(task, n)


def parse_int_list(text: str, what: str) -> list[int]:
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise CliError(f"{what} must be comma-separated integers, got '{text}'") from None
    if not values:
        raise CliError(f"no {what} given")
    return values


def results_table(summary: list[dict], title: str) -> Table:
    """Mean ± sample std per policy and setting, in the paper's main-table layout."""
    table = Table(title=title, title_justify="left")
    for column, justify in (
        ("policy", "left"),
        ("setting", "left"),
        ("episodes", "right"),
        ("cumulative reward", "right"),
        ("volume", "right"),
        ("violation rate", "right"),
        ("slippage", "right"),
        ("artificial liq. (MWh)", "right"),
    ):
        table.add_column(column, justify=justify)
    for entry in summary:
        m = entry["metrics"]

        def fmt(name: str, digits: int) -> str:
            return f"{m[name]['mean']:.{digits}f} ± {m[name]['std']:.{digits}f}"

        table.add_row(
            entry["policy"],
            entry["setting"],
            str(entry["episodes"]),
            fmt("cumulative_reward", 2),
            fmt("episode_volume", 3),
            fmt("physics_violation_rate", 4),
            fmt("mean_slippage", 4),
            fmt("artificial_liquidity_MWh", 4),
        )
    return table


def show_files(files: dict[str, Path], heading: str = "files") -> None:
    console.print(f"[bold]{heading}:[/bold]")
    for name, path in files.items():
        console.print(f"  {name:<24} {path}", highlight=False)


def invoked_command() -> list[str]:
    """The command line as it may be recorded: credentials redacted (see docs/output_safety.md)."""
    from ..redaction import redact_command

    return redact_command(["solarchain-eval", *sys.argv[1:]])
