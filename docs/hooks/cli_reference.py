"""mkdocs hook: the CLI reference page is generated from the typer app at build time.

A page containing the marker line ``<!-- cli-reference -->`` gets it replaced by one section per
command of ``solarchain-eval`` (usage, help text, every option with its type, default and help),
read from the click command that typer builds (typer vendors its own copy of click, so the
code below relies only on the attributes every click version has). The reference therefore cannot drift from the
code: a renamed option or a new command shows up at the next ``mkdocs build``.
"""

from __future__ import annotations

import re
from typing import Any

MARKER = "<!-- cli-reference -->"
PROGRAM = "solarchain-eval"

# typer's "rich" markup in help strings: [bold]x[/bold] → **x**, other tags dropped.
_BOLD = re.compile(r"\[bold\](.*?)\[/bold\]", re.DOTALL)
_TAG = re.compile(r"\[/?[a-z][a-z _.-]*\]")


def _plain(text: str | None) -> str:
    if not text:
        return ""
    text = _BOLD.sub(r"**\1**", text)
    text = _TAG.sub("", text)
    # Single newlines inside a paragraph are hard wraps; blank lines separate paragraphs.
    paragraphs = [" ".join(p.split()) for p in re.split(r"\n\s*\n", text.strip())]
    return "\n\n".join(p for p in paragraphs if p)


def _cell(text: str) -> str:
    """Text safe inside a Markdown table cell (a pipe would end the cell)."""
    return text.replace("|", "\\|").replace("\n", " ")


def _option_row(param: Any, ctx: Any) -> str | None:
    """One table row, from the same help record ``--help`` prints (names, metavar, help, default)."""
    record = param.get_help_record(ctx)
    if record is None:  # hidden option, or an argument without help text
        if param.param_type_name != "argument":
            return None
        record = (param.name.upper(), "required" if param.required else "")
    names, help_text = record
    # "<" outside code would open an HTML tag in Markdown (e.g. "<output_dir>").
    return f"| `{_cell(names)}` | {_cell(_plain(help_text)).replace('<', '&lt;')} |"


def _command_section(command: Any, path: list[str], parent: Any) -> list[str]:
    ctx = command.context_class(command, info_name=path[-1], parent=parent)
    level = min(len(path) + 1, 4)
    lines = [f"{'#' * level} `{' '.join(path)}`", ""]
    help_text = _plain(command.help)
    if help_text:
        lines += [help_text, ""]
    lines += ["```text", command.get_usage(ctx).strip(), "```", ""]
    rows = [row for row in (_option_row(p, ctx) for p in command.params) if row is not None]
    if rows:
        header = ["| argument / option | description |", "|---|---|"]
        lines += [*header, *rows, "| `--help` | Show this message and exit. |", ""]
    if hasattr(command, "list_commands"):
        for name in command.list_commands(ctx):
            sub = command.get_command(ctx, name)
            if sub is not None and not sub.hidden:
                lines += _command_section(sub, [*path, name], ctx)
    return lines


def cli_reference_markdown() -> str:
    """The whole reference as Markdown, from ``typer.main.get_command`` over the app."""
    import typer.main

    from solarchain_eval.cli import app

    return "\n".join(_command_section(typer.main.get_command(app), [PROGRAM], None))


def on_page_markdown(markdown: str, page: Any, **_: Any) -> str:
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, cli_reference_markdown())
