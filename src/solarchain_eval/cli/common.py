"""Shared CLI helpers: error reporting, progress bars, result tables."""

from __future__ import annotations

import functools
import os
import sys
import traceback
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TypeVar

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table
from rich.text import Text

from ..common.errors import NamesOptions, OptionsError, SolarChainError, flag_of
from ..common.redaction import redact_text
from ..config import check_seeds
from ..tasks.base import headline_metrics_of
from ..tasks.registry import DEFAULT_TASK, get_task
from .help import get_current_context

# Every text printed comes from users, files or servers somewhere (paths, city names, server
# errors), so rich never interprets markup or emoji codes: "[/x]" cannot crash, "[bold]" and
# "[redacted]" stay visible, "Foo:100:200" is not an emoji. Styling uses Text objects instead.
_PLAIN = {"markup": False, "emoji": False, "highlight": False}
# Tables stay readable when output goes to a file or CI log (rich would assume 80 columns).
console = Console(width=None if Console().is_terminal else 140, **_PLAIN)
err_console = Console(stderr=True, **_PLAIN)

#: Errors caused by the user's input: reported in one line, exit status 2, no traceback. Every
#: error the package raises on purpose is a SolarChainError (common/errors.py); anything else is a
#: bug and keeps its traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (SolarChainError,)
# Library errors name options by field; the CLI shows them as the flags the user typed (see option_errors).
EXIT_USAGE = 2

F = TypeVar("F", bound=Callable)

#: ``--task NAME`` of the commands that evaluate a market.
TASK = typer.Option(
    DEFAULT_TASK,
    "--task",
    metavar="NAME",
    help="The task (market) to evaluate: solar (the paper's) or one an installed package registers in the "
    "solarchain_eval.tasks entry-point group. See docs/architecture.md#add-a-task.",
)


class CliError(OptionsError):
    """A problem with the command's arguments or inputs, reported without a traceback."""


def register_user_error(*types: type[BaseException]) -> None:
    """Add error types from outside the package (whose own errors are all covered) to the list."""
    global USER_ERRORS
    USER_ERRORS = tuple(dict.fromkeys((*USER_ERRORS, *types)))


#: Library field names whose command-line option has another name.
FIELD_FLAGS = {"run_dir": "--out", "root": "--out", "tensorboard_dir": "--tensorboard", "lagrangian": "--cost-limit"}


def cli_error(error: Exception) -> CliError:
    """A :class:`CliError` with ``error``'s message, its options named by flag (and the user's
    exception behind it, for :data:`DEBUG_VARIABLE`)."""
    failure = CliError(error.message_for(_flag_of) if isinstance(error, NamesOptions) else str(error))
    failure.user_error = getattr(error, "user_error", None)  # type: ignore[attr-defined]
    return failure


#: Set to 1 to see, above the one-line error, the traceback of the user's code that caused it
#: (an agent's import, constructor or hook), else of the error itself.
DEBUG_VARIABLE = "SOLARCHAIN_DEBUG"


def _show_traceback(error: BaseException) -> None:
    if os.environ.get(DEBUG_VARIABLE, "") in ("", "0"):
        return
    shown = getattr(error, "user_error", None) or error
    sys.stderr.write("".join(traceback.format_exception(shown)))


def _flag_of(field: str) -> str:
    """The flag of the running command's parameter ``field`` (typer's convention if it has none)."""
    if field in FIELD_FLAGS:
        return FIELD_FLAGS[field]
    context = get_current_context(silent=True)
    if context is not None:
        for param in context.command.params:
            if param.name == field and param.opts:
                return max(param.opts, key=len)  # the long form
    return flag_of(field)


def reports_errors(func: F) -> F:
    """Turn user errors into a one-line message and exit status 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except USER_ERRORS as error:
            _show_traceback(error)
            message = error.message_for(_flag_of) if isinstance(error, NamesOptions) else str(error)
            message = redact_text(message)  # a spec or URL the error repeats may carry credentials
            err_console.print(Text.assemble(("error:", "bold red"), f" {message}"), soft_wrap=True)
            raise typer.Exit(EXIT_USAGE) from None
        except KeyboardInterrupt:
            err_console.print(Text.assemble(("interrupted", "yellow"), ": no partial output file was left behind"))
            raise typer.Exit(130) from None

    return wrapper  # type: ignore[return-value]


@contextmanager
def progress_bar(description: str, total: int, *, enabled: bool = True) -> Iterator[Callable[[int], None]]:
    """A rich progress bar; yields ``advance(n)``. Hidden when stderr is not a terminal."""
    if not enabled:
        yield lambda n=1: None
        return
    progress = Progress(
        TextColumn("{task.description}", style="bold", markup=False),
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


def refuse_file_out(out: Path | None, flag: str = "--out") -> None:
    """An output folder that is an existing file is the user's mistake: one line, before any work."""
    if out is not None and out.exists() and not out.is_dir():
        raise CliError(f"{flag} {out} is an existing file, not a folder")


def parse_int_list(text: str, what: str) -> list[int]:
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise CliError(f"{what} must be comma-separated integers, got '{text}'") from None
    if not values:
        raise CliError(f"no {what} given")
    return values


def parse_seeds(text: str) -> list[int]:
    """Comma-separated run seeds: distinct integers in 0..2**32 - 1."""
    seeds = parse_int_list(text, "seeds")
    check_seeds(seeds)
    return seeds


#: The results table's metric columns: (metrics.csv column, header, digits), in the paper's main-table layout.
RESULT_COLUMNS = (
    ("cumulative_reward", "cumulative reward", 2),
    ("episode_volume", "volume", 3),
    ("physics_violation_rate", "violation rate", 4),
    ("mean_slippage", "slippage", 4),
    ("artificial_liquidity_MWh", "artificial liq. (MWh)", 4),
)


def result_columns(task: str) -> Sequence[tuple[str, str, int]]:
    """The results table's columns for ``task``: the paper's for the solar market, else the task's
    headline metrics (:func:`~solarchain_eval.tasks.base.headline_metrics_of`; every declared metric
    is in ``metrics.csv``)."""
    if task == DEFAULT_TASK:
        return RESULT_COLUMNS
    return [(m.name, m.name, 4) for m in headline_metrics_of(get_task(task))]


def results_table(
    summary: list[dict],
    title: str,
    access: dict[str, str] | None = None,
    columns: Sequence[tuple[str, str, int]] = RESULT_COLUMNS,
) -> Table:
    """Mean ± sample std per policy and setting of ``columns`` (default :data:`RESULT_COLUMNS`; another
    task's metrics); policies in ``access`` marked ``"privileged"`` (they saw the environment) or
    ``"isolated"`` (they ran in a process of their own) are labelled so."""
    table = Table(title=title, title_justify="left")
    for column, justify in (("policy", "left"), ("setting", "left"), ("episodes", "right")):
        table.add_column(column, justify=justify)
    for _, header, _ in columns:
        table.add_column(header, justify="right")
    for entry in summary:
        m = entry["metrics"]

        def fmt(name: str, digits: int, m: dict = m) -> str:
            std = m[name]["std"]  # None for a single episode (undefined, see summarize)
            return f"{m[name]['mean']:.{digits}f} ± " + ("–" if std is None else f"{std:.{digits}f}")

        label = (access or {}).get(entry["policy"])
        table.add_row(
            entry["policy"] + (f" ({label})" if label in ("privileged", "isolated") else ""),
            entry["setting"],
            str(entry["episodes"]),
            *(fmt(name, digits) for name, _, digits in columns),
        )
    return table


#: The main table's metrics and their short headers (the paper's column order).
PAPER_COLUMNS = {
    "cumulative_reward": "reward",
    "episode_volume": "volume",
    "physics_violation_rate": "violation",
    "mean_slippage": "slippage",
    "artificial_liquidity_MWh": "art. liquidity",
}


def paper_results_table(comparison, title: str) -> tuple[Table, str]:
    """The baselines' main table beside the paper's published cells, and a line on whether they agree.

    ``comparison`` is a :class:`~solarchain_eval.report.against_paper.tables.BaselineComparison`: per
    policy and metric the run's "mean ± std" at the paper's decimals and the paper's.
    """
    table = Table(title=title, title_justify="left")
    table.add_column("policy")
    table.add_column("episodes", justify="right")
    for header in PAPER_COLUMNS.values():
        table.add_column(header, justify="right")
        table.add_column("paper", justify="right", style="dim")
    for row in comparison.rows.to_dict("records"):
        cells = [row["policy"], str(row["episodes"])]
        for name in PAPER_COLUMNS:
            ours = Text(row[name], style="" if row[f"{name}_equal"] else "bold red")
            cells += [ours, row[f"{name}_paper"]]
        table.add_row(*cells)
    if comparison.all_equal:
        line = f"every printed digit equals the paper's main table ({comparison.cells} of {comparison.cells} cells)"
    else:
        line = (
            f"{comparison.cells - comparison.equal_cells} of {comparison.cells} cells differ from the paper's "
            "main table (in red)"
        )
    return table, line


def say(message: str, *, style: str | None = None, err: bool = True) -> None:
    """Print one plain-text line (no markup); long paths are never broken by rich's wrapping."""
    (err_console if err else console).print(Text(message, style=style or ""), soft_wrap=True)


def show_files(files: dict[str, Path], heading: str = "files") -> None:
    say(f"{heading}:", style="bold", err=False)
    for name, path in files.items():
        say(f"  {name:<24} {path}", err=False)


def invoked_command() -> list[str]:
    """The command line as it may be recorded: credentials redacted (see docs/output_safety.md)."""
    from ..common.redaction import redact_command

    return redact_command(["solarchain-eval", *sys.argv[1:]])
