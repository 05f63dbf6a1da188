"""A report table: numeric data (the CSV) plus column formatters (Markdown, LaTeX, HTML).

A table keeps one numeric row per printed row at full precision; each :class:`Column` turns a
data row into the printed cell. Rendering is pure string work, so the same data always gives
byte-identical files.
"""

from __future__ import annotations

import html
import io
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from .statistics import SampleSize

Row = Mapping[str, Any]


@dataclass(frozen=True)
class Column:
    """One printed column.

    Attributes
    ----------
    header
        Markdown/HTML header (Unicode, e.g. "Δ Reward").
    render
        Formats one data row as the cell text ("±" and "–" are turned into LaTeX by the LaTeX writer).
    latex
        LaTeX header; defaults to ``header`` escaped.
    align
        LaTeX/Markdown alignment: "l", "c" or "r" (or a LaTeX ``p{..}`` spec, left in Markdown).
    """

    header: str
    render: Callable[[Row], str]
    latex: str | None = None
    align: str = "c"


@dataclass
class ReportTable:
    """A finished table.

    Attributes
    ----------
    key
        File stem (``tables/<key>.md`` ...).
    label
        LaTeX label (the paper's where the paper has the table).
    title, caption
        Short title and the caption (the paper's wording where it has one).
    columns
        Printed columns.
    data
        Numeric rows, full precision: what the CSV holds.
    basis
        The sample behind the table: rows, n, distinct episodes.
    notes
        Anything the reader must know (dropped rows, overlap, fallbacks).
    wide
        Whether LaTeX uses ``table*``.
    """

    key: str
    label: str
    title: str
    caption: str
    columns: list[Column]
    data: pd.DataFrame
    basis: str
    notes: list[str] = field(default_factory=list)
    wide: bool = True

    def cells(self) -> list[list[str]]:
        """The printed rows (plain text)."""
        return [[column.render(row) for column in self.columns] for row in self.data.to_dict("records")]


@dataclass(frozen=True)
class Skipped:
    """A table or figure the data cannot support, and why."""

    key: str
    title: str
    reason: str


# ----------------------------------------------------------------------------- number formats


def fixed(value: float, digits: int) -> str:
    """``value`` with ``digits`` decimals; "n/a" for NaN; never "-0.00"."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    text = f"{float(value):.{digits}f}"
    if text.startswith("-") and float(text) == 0.0:
        text = text[1:]
    return text


def pm(mean: float, std: float, digits: int) -> str:
    """ "mean ± std" with the same number of decimals (the paper's main-table cell)."""
    return f"{fixed(mean, digits)} ± {fixed(std, digits)}"


def span(low: float, high: float, digits: int) -> str:
    """ "low–high" (rendered "low--high" in LaTeX)."""
    return f"{fixed(low, digits)}–{fixed(high, digits)}"


def with_interval(value: float, low: float, high: float, digits: int) -> str:
    """ "value [low, high]" for an estimate with its confidence interval."""
    return f"{fixed(value, digits)} [{fixed(low, digits)}, {fixed(high, digits)}]"


def p_value(value: float) -> str:
    """A p-value: 3 significant digits, scientific below 0.001."""
    if value is None or math.isnan(value):
        return "n/a"
    return f"{value:.3g}" if value >= 1e-3 else f"{value:.2e}"


def cell(name: str, digits: int) -> Callable[[Row], str]:
    """Formatter of a numeric data column."""
    return lambda row: fixed(row[name], digits)


def cell_pm(name: str, digits: int) -> Callable[[Row], str]:
    """Formatter of ``<name>_mean ± <name>_std``."""
    return lambda row: pm(row[f"{name}_mean"], row[f"{name}_std"], digits)


def text(name: str) -> Callable[[Row], str]:
    """Formatter of a text data column."""
    return lambda row: str(row[name])


def integer(name: str) -> Callable[[Row], str]:
    return lambda row: str(int(row[name]))


# ----------------------------------------------------------------------------- sample basis


def _range(values: Sequence[int]) -> str:
    low, high = min(values), max(values)
    return str(low) if low == high else f"{low}–{high}"


#: Below this many distinct start days behind a row, every statistic carries a visible caveat: the
#: cluster bootstrap resamples start days, and a handful of clusters cannot support an interval.
SMALL_SAMPLE_START_DAYS = 5
SMALL_SAMPLE_CAVEAT = "Small sample"


def basis_sentence(sizes: Sequence[SampleSize], unit: str) -> str:
    """State n and the distinct episodes behind each row, flagging overlap.

    ``unit`` names what a row counts ("rollouts", "paired rollouts", "steps").
    """
    if not sizes:
        return f"n = 0 {unit}."
    n = [s.n for s in sizes]
    seeds = [s.episode_seeds for s in sizes]
    days = [s.start_days for s in sizes]
    sentence = (
        f"n = {_range(n)} {unit} per row, behind them {_range(seeds)} distinct episode seeds and "
        f"{_range(days)} distinct start days"
    )
    overlap = unit != "steps" and any(s.n > s.start_days for s in sizes)
    if overlap:
        sentence += " (rollouts overlap: rows are not independent samples)"
    sentence += "."
    if min(days) < SMALL_SAMPLE_START_DAYS:
        sentence += (
            f" {SMALL_SAMPLE_CAVEAT}: as few as {min(days)} distinct start day(s) behind a row; standard "
            "deviations, intervals and p-values rest on too few independent episodes to be trusted."
        )
    return sentence


# ----------------------------------------------------------------------------- writers


_LATEX_ESCAPES = {"&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_", "{": r"\{", "}": r"\}"}


_LATEX_SYMBOLS = {
    "±": r"$\pm$",
    "–": "--",
    "Δ": r"$\Delta$",
    "≥": r"$\geq$",
    "×": r"$\times$",
    "½": r"$\frac{1}{2}$",
    "κ": r"$\kappa$",
    "ℓ": r"$\ell$",
    "α": r"$\alpha$",
    "ν": r"$\nu$",
    "∝": r"$\propto$",
    "↑": r"$\uparrow$",  # a declared metric's direction (report/task_summary.py)
    "↓": r"$\downarrow$",
    "·": r"$\cdot$",
    "−": r"$-$",  # the minus of a contrast's "treated − base" (report/task_contrast.py)
}


def latex_escape(value: str) -> str:
    """Escape LaTeX specials and turn the symbols the report prints ("±", "–", "Δ", "×", ...) into LaTeX."""
    return "".join(_LATEX_ESCAPES.get(ch) or _LATEX_SYMBOLS.get(ch, ch) for ch in value)


def to_markdown(table: ReportTable, *, heading: bool = True) -> str:
    """GitHub-flavoured Markdown: a heading, the table, caption, basis and notes."""
    aligns = {"l": ":--", "c": ":-:", "r": "--:"}
    lines = [f"### {table.title}", ""] if heading else []
    lines.append("| " + " | ".join(c.header for c in table.columns) + " |")
    lines.append("|" + "|".join(aligns.get(c.align, ":--") for c in table.columns) + "|")
    for row in table.cells():
        lines.append("| " + " | ".join(value.replace("|", "\\|") for value in row) + " |")
    basis, caveat = _split_caveat(table.basis)
    lines += ["", table.caption, "", f"*{basis}*"] + ([f"**{caveat}**"] if caveat else [])
    lines += [f"- Note: {note}" for note in table.notes]
    return "\n".join(lines) + "\n"


def to_latex(table: ReportTable) -> str:
    """A booktabs table (``table*`` when wide) with the paper's label."""
    env = "table*" if table.wide else "table"
    spec = "".join(c.align for c in table.columns)
    lines = [
        f"\\begin{{{env}}}[t]",
        "\\centering",
        f"\\caption{{{latex_escape(table.caption)}}}",
        f"\\label{{{table.label}}}",
        f"\\begin{{tabular}}{{{spec}}}",
        "\\toprule",
        " & ".join(c.latex if c.latex is not None else latex_escape(c.header) for c in table.columns) + " \\\\",
        "\\midrule",
    ]
    lines += [" & ".join(latex_escape(value) for value in row) + " \\\\" for row in table.cells()]
    lines += ["\\bottomrule", "\\end{tabular}"]
    notes = " ".join([table.basis, *table.notes])
    lines += [f"\\par\\smallskip{{\\footnotesize {latex_escape(notes)}}}", f"\\end{{{env}}}"]
    return "\n".join(lines) + "\n"


def to_csv(table: ReportTable) -> str:
    """The numeric data at full precision (Unix newlines)."""
    buffer = io.StringIO()
    table.data.to_csv(buffer, index=False, lineterminator="\n")
    return buffer.getvalue()


def _split_caveat(basis: str) -> tuple[str, str]:
    """The basis sentence and its small-sample caveat ("" when there is none), to show the caveat apart."""
    at = basis.find(f" {SMALL_SAMPLE_CAVEAT}:")
    return (basis, "") if at < 0 else (basis[:at], basis[at + 1 :])


def _html_basis(basis: str) -> str:
    text, caveat = _split_caveat(basis)
    shown = f'<p class="basis">{html.escape(text)}</p>\n'
    return shown + (f'<p class="caveat">{html.escape(caveat)}</p>\n' if caveat else "")


def to_html(table: ReportTable) -> str:
    """An HTML ``<table>`` with caption, basis and notes (no scripts, no external resources)."""
    head = "".join(f"<th>{html.escape(c.header)}</th>" for c in table.columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(value)}</td>" for value in row) + "</tr>\n" for row in table.cells()
    )
    notes = "".join(f"<li>{html.escape(note)}</li>" for note in table.notes)
    return (
        f'<figure class="table" id="{html.escape(table.key)}">\n'
        f"<figcaption><strong>{html.escape(table.title)}.</strong> {html.escape(table.caption)}</figcaption>\n"
        f"<table>\n<thead><tr>{head}</tr></thead>\n<tbody>\n{body}</tbody>\n</table>\n"
        + _html_basis(table.basis)
        + (f'<ul class="notes">{notes}</ul>\n' if notes else "")
        + "</figure>\n"
    )
