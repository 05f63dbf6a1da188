"""Plain-text ``--help`` that reads right at 80 columns.

Help is rendered by click's formatter (typer's rich panels squeeze option names at 80 columns
and show a ``<bool>`` metavar on every flag). click re-flows docstring paragraphs, so hard
wraps in the source do not show; this formatter also keeps hyphenated words, option names and
dates (``--llm-cache``, ``YYYY-MM-DD``) whole instead of breaking them at a hyphen.
"""

from __future__ import annotations

from typing import Any

from typer.core import TyperGroup

try:  # typer >= 0.22 runs on its own vendored copy of click
    from typer import _click as click
    from typer._click.globals import get_current_context  # noqa: F401  (used by cli/common)
    from typer._click.utils import make_default_short_help  # noqa: F401  (used by cli/__init__)
except ImportError:  # pragma: no cover - older typer uses click itself
    import click  # type: ignore[no-redef]
    from click import get_current_context  # type: ignore[no-redef]  # noqa: F401
    from click.utils import make_default_short_help  # type: ignore[no-redef]  # noqa: F401

#: Stands in for "-" while click wraps (U+2011, non-breaking hyphen: same width, no break).
_NO_BREAK_HYPHEN = "\u2011"


class HelpFormatter(click.HelpFormatter):
    """click's formatter with hyphens that never end a line."""

    def write(self, string: str) -> None:
        super().write(string.replace(_NO_BREAK_HYPHEN, "-"))

    def write_text(self, text: str) -> None:
        super().write_text(text.replace("-", _NO_BREAK_HYPHEN))

    def write_dl(self, rows: Any, col_max: int = 30, col_spacing: int = 2) -> None:
        rows = [(first, second.replace("-", _NO_BREAK_HYPHEN)) for first, second in rows]
        super().write_dl(rows, col_max, col_spacing)


class HelpContext(click.Context):
    formatter_class = HelpFormatter


#: Plain metavars for typer's type labels (``<list[str]>``, ``<int range>``, ``<path>``).
_METAVARS = {"str": "TEXT", "int": "INTEGER", "float": "FLOAT", "path": "PATH", "file": "PATH", "directory": "DIR"}


def plain_metavars(command: Any) -> None:
    """Give every option without an explicit metavar a plain one (flags and choices keep theirs)."""
    for param in command.params:
        if param.param_type_name != "option" or param.metavar is not None or getattr(param, "is_flag", False):
            continue
        descriptor = getattr(param, "type_descriptor", None)
        if descriptor is None or descriptor.is_choice:
            continue
        label = param.display_type(None).strip("<>").replace(" range", "")
        if label.startswith("list[") and label.endswith("]"):
            label = label[5:-1]
        if label in _METAVARS:
            param.metavar = _METAVARS[label]


class HelpGroup(TyperGroup):
    """A typer group whose commands (and itself) format help with :class:`HelpFormatter`."""

    context_class = HelpContext

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for command in self.commands.values():
            if not isinstance(command, TyperGroup):
                command.context_class = HelpContext
                plain_metavars(command)
