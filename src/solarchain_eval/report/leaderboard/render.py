"""A leaderboard's files: ``leaderboard.csv``, ``leaderboard.md``, the self-contained
``leaderboard.html`` (inline CSS and script, the Pareto figure as a PNG data URI, tables sorted by
clicking a column header) and ``pareto.png``/``pareto.svg`` (a suite board's: its performance
profile, ``performance_profile.png``/``.svg``, and the columns of :mod:`.suite_board`).

Rendering is pure: the same board gives byte-identical files.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from typing import Any

import pandas as pd

from ...tasks.registry import DEFAULT_TASK
from ..naming import setting_label
from ..task_summary import ARROWS
from .columns import DisplayColumn as DisplayColumn
from .columns import display_columns as display_columns
from .columns import missing
from .columns import shown_policy as shown_policy
from .pareto import SOLAR_PARETO, ParetoAxes, pareto_figure
from .ranking import RANKED, REFERENCE, BoardLayout, BoardSection, Leaderboard
from .suite_board import PROFILE, suite_display_columns, suite_profile_figure, suite_protocol_lines, suite_reading

#: The Pareto figure's file stem.
FIGURE = "pareto"


def board_columns(board: Leaderboard) -> list[DisplayColumn]:
    """The printed columns of ``board``'s tables: a suite board's (:mod:`.suite_board`) or its task's."""
    return (
        suite_display_columns(board)
        if board.suite is not None
        else display_columns(board.options.confidence, board.layout)
    )


def _title(board: Leaderboard) -> str:
    return "SolarChain-Eval suite leaderboard" if board.suite is not None else "SolarChain-Eval leaderboard"


def _id_label(board: Leaderboard) -> str:
    return "suite protocol id" if board.suite is not None else "protocol id"


def _cells(section: BoardSection, columns: Sequence[DisplayColumn]) -> list[tuple[dict[str, Any], list[str]]]:
    rows = section.rows().to_dict("records")
    return [(row, [c.render(row) for c in columns]) for row in rows]


def _protocol_lines(board: Leaderboard) -> list[tuple[str, str]]:
    if board.suite is not None:
        return suite_protocol_lines(board)
    protocol = board.protocol
    dataset = ", ".join(f"{name} {digest[:12]}" for name, digest in protocol.get("dataset_sha256", {}).items())
    task = [("Task", board.layout.task)] if board.layout.task != DEFAULT_TASK else []  # solar boards as before
    return [
        *task,
        ("Board protocol id", board.board_id),
        ("Environment", str(protocol.get("env"))),
        ("Dataset (sha256)", dataset or "not recorded"),
        ("Run seeds", ", ".join(str(s) for s in protocol.get("run_seeds", []))),
        ("Episodes per run seed", str(protocol.get("episodes"))),
        ("Episode-seed rule", str(protocol.get("episode_seed_rule"))),
        ("Task configuration (sha256, reward switch aside)", str(protocol.get("config_sha256", ""))[:12]),
        ("Records schema", str(protocol.get("records_schema_version"))),
    ]


def _either(names: Sequence[str]) -> str:
    """``a, b or c``."""
    return " or ".join([", ".join(names[:-1]), names[-1]]) if len(names) > 1 else "".join(names)


def _reading(board: Leaderboard) -> list[str]:
    if board.suite is not None:
        return suite_reading(board)
    layout = board.layout
    level = f"{board.options.confidence:.0%}"
    words = layout.ranked.name.replace("_", " ")
    short = layout.label(layout.ranked) or words
    if layout.paper is not None:  # the paper's board: its five safety metrics
        others = "Safety metrics are means over rollouts; lower is better for each."
    else:
        others = (
            "The other metrics are means over rollouts, headed by their name, unit and direction "
            f"({ARROWS['higher']} higher is better, {ARROWS['lower']} lower is better, {ARROWS['none']} neither)."
        )
    return [
        f"Policies are ranked per setting by mean {words}. Intervals are {level} percentile intervals of "
        f"a bootstrap that resamples whole start days ({board.options.n_resamples} resamples, seed "
        f"{board.options.seed}): rollouts that start on the same day are not independent.",
        "IQM is the interquartile mean (the mean of the middle 50 % of rollouts).",
        "P(> best baseline) is P(X > Y) + ½ P(X = Y) over paired episodes (same run seed and episode, so the "
        f"same episode seed and start day), where Y is the setting's best baseline ({_either(layout.baselines)}, "
        f"by mean {short}); 0.5 means no better than it.",
        f"{others} Access: isolated agents ran in a "
        "process of their own and received only observations, step info and the public episode context; "
        "in-process ones received the same but ran in the evaluating process, where their code could reach "
        "the environment; privileged ones (and every agent behind the Planner/Auditor layer) were handed "
        "the environment's internals.",
    ]


def _section_notes(section: BoardSection, board: Leaderboard) -> list[str]:
    layout = board.layout
    if board.suite is not None:
        high = board.suite.reference[1]
        return [f"P(> {high}) compares every policy with {high}, the suite's upper reference (score 1)."]
    notes = []
    if section.best_baseline is None:
        notes.append(
            f"No baseline ({', '.join(layout.baselines)}) was evaluated in this setting: no probability of improvement."
        )
    else:
        notes.append(f"Best baseline: {shown_policy(layout, section.best_baseline)}.")
    if section.reference is not None:
        notes.append(
            "Rows ranked 'paper' are the paper's published values for this protocol (mean ± sample std), "
            "shown for reference and not ranked."
        )
    return notes


def pareto_axes(layout: BoardLayout) -> ParetoAxes | None:
    """The figure's axes: the paper's for a task with a paper reference; else the ranked metric against
    the first shown safety metric whose direction is ``lower`` (else any such metric; None: no figure)."""
    if layout.paper is not None:
        return SOLAR_PARETO
    lower = [m for m in layout.shown if m.direction == "lower"]
    costs = [m for m in lower if m.dimension == "safety"] + lower
    if not costs:
        return None
    x, y = costs[0], layout.ranked
    return ParetoAxes(
        f"{x.name}_mean",
        f"{y.name}_mean",
        f"{x.name} ({x.unit}, lower is better)",
        f"Mean {y.name} ({y.unit})",
        f"{y.name} vs {x.name}",
    )


def board_figure(board: Leaderboard) -> tuple[str, str, str] | None:
    """The board's figure: (file stem, title, caption), or None when it has none (a suite board's
    performance profile; else the Pareto figure of :func:`pareto_axes`)."""
    if board.suite is not None:
        caption = (
            "For each threshold τ, the fraction of each policy's normalised scores (every entry and episode) "
            "above τ; dotted lines mark the reference levels 0 and 1."
        )
        return PROFILE, f"suite {board.suite.suite}: performance profile", caption
    axes = pareto_axes(board.layout)
    if axes is None:
        return None
    if axes is SOLAR_PARETO:
        caption = (
            "Mean cumulative reward against mean artificial liquidity per policy and setting, with "
            "the reward's interval; outlined points joined by the dashed line form the Pareto front (no other "
            "policy has both more reward and less artificial liquidity)."
        )
    else:
        caption = (
            f"{axes.y_label} against {axes.x_label} per policy and setting, with the ranked metric's interval; "
            "outlined points joined by the dashed line form the Pareto front."
        )
    return FIGURE, axes.title, caption


def render_markdown(board: Leaderboard, figure: bool = True) -> str:
    """``leaderboard.md``: the protocol, the inputs, one table per setting and the figure's link."""
    columns = board_columns(board)
    drawn = board_figure(board)
    lines = [f"# {_title(board)}", ""]
    lines += [f"- {name}: `{value}`" for name, value in _protocol_lines(board)]
    lines += ["", "Inputs:", ""] + [f"- `{source}`" for source in board.sources] + [""]
    lines += [" ".join(_reading(board)), ""]
    if figure and drawn is not None:
        stem, title, _ = drawn
        lines += [f"![{title}{', Pareto front highlighted' if stem == FIGURE else ''}]({stem}.png)", ""]
    for section in board.sections:
        lines += [f"## {setting_label(section.setting)} ({_id_label(board)} `{section.protocol_id}`)", ""]
        lines.append("| " + " | ".join(c.header for c in columns) + " |")
        lines.append("|" + "|".join("--:" if c.numeric else ":--" for c in columns) + "|")
        for _, cells in _cells(section, columns):
            lines.append("| " + " | ".join(cell.replace("|", "\\|") for cell in cells) + " |")
        lines += ["", f"*{section.basis}*", ""] + [f"- {note}" for note in _section_notes(section, board)] + [""]
    if board.notes:
        lines += ["## Notes", ""] + [f"- {note}" for note in board.notes] + [""]
    return "\n".join(lines)


CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0 auto;max-width:1500px;padding:1.5rem;color:#1d1d1f;line-height:1.45}
h2{border-bottom:2px solid #e5e5e5;padding-bottom:.2rem;margin-top:2rem}
.meta{color:#555;font-size:.9rem}dl.protocol{display:grid;grid-template-columns:max-content 1fr;gap:.1rem 1rem;font-size:.88rem}
dl.protocol dt{font-weight:600}dl.protocol dd{margin:0;font-family:ui-monospace,Menlo,monospace}
.scroll{overflow-x:auto}table{border-collapse:collapse;font-size:.86rem;margin:.4rem 0}
th,td{padding:.28rem .6rem;border-bottom:1px solid #e2e2e2;white-space:nowrap;text-align:right}
th{border-top:2px solid #333;border-bottom:1px solid #333;background:#fafafa;cursor:pointer;user-select:none}
th:hover,th:focus{background:#eef4ff}th[aria-sort=ascending]::after{content:" \\25B2"}th[aria-sort=descending]::after{content:" \\25BC"}
td.text,th.text{text-align:left}tr.reference td{font-style:italic;color:#555;background:#fbfaf3}
.basis{font-size:.82rem;color:#444;font-style:italic}ul.notes{font-size:.84rem;color:#333}
figure{margin:1rem 0}figure img{max-width:min(100%,1100px);height:auto}figcaption{font-size:.88rem}
"""

SCRIPT = """
(function () {
  function key(row, index, numeric) {
    var text = row.cells[index].getAttribute('data-value');
    return numeric ? (text === '' ? NaN : parseFloat(text)) : text;
  }
  function sortBy(table, th, index, direction) {
    var numeric = th.getAttribute('data-type') === 'number';
    var sign = direction === 'ascending' ? 1 : -1;
    var body = table.tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {
      var x = key(a, index, numeric), y = key(b, index, numeric);
      if (numeric) {
        if (isNaN(x) || isNaN(y)) { return isNaN(x) === isNaN(y) ? 0 : (isNaN(x) ? 1 : -1); }
        return sign * (x - y);
      }
      return sign * x.localeCompare(y);
    });
    rows.forEach(function (row) { body.appendChild(row); });
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (cell) { cell.removeAttribute('aria-sort'); });
    th.setAttribute('aria-sort', direction);
  }
  Array.prototype.forEach.call(document.querySelectorAll('table.board'), function (table) {
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, index) {
      function activate() {
        var best = th.getAttribute('data-best');
        var other = best === 'ascending' ? 'descending' : 'ascending';
        sortBy(table, th, index, th.getAttribute('aria-sort') === best ? other : best);
      }
      th.addEventListener('click', activate);
      th.addEventListener('keydown', function (event) {
        if (event.key === 'Enter' || event.key === ' ') { event.preventDefault(); activate(); }
      });
    });
  });
})();
"""


def _escape(value: Any) -> str:
    return html.escape(str(value))


def _sort_value(value: Any, numeric: bool) -> str:
    if numeric:
        return "" if missing(value) or value == "" else repr(float(value))
    return "" if missing(value) else str(value)


def _head(column: DisplayColumn) -> str:
    kind = "number" if column.numeric else "text"
    sort = ' aria-sort="ascending"' if column.key == "rank" else ""  # the board comes ranked
    css = "" if column.numeric else ' class="text"'
    return f'<th scope="col" tabindex="0" data-type="{kind}" data-best="{column.best}"{sort}{css}>{_escape(column.header)}</th>'


def _table(section: BoardSection, columns: Sequence[DisplayColumn]) -> str:
    head = "".join(_head(c) for c in columns)
    body = []
    for row, cells in _cells(section, columns):
        tds = "".join(
            f'<td data-value="{_escape(_sort_value(row.get(c.key), c.numeric))}"'
            + ("" if c.numeric else ' class="text"')
            + f">{_escape(cell)}</td>"
            for c, cell in zip(columns, cells, strict=True)
        )
        kind = "reference" if row["row_kind"] == REFERENCE else RANKED
        body.append(f'<tr class="{kind}" data-policy="{_escape(row["policy"])}">{tds}</tr>')
    return (
        f'<div class="scroll"><table class="board" id="board-{_escape(section.setting)}">'
        f"<thead><tr>{head}</tr></thead><tbody>\n" + "\n".join(body) + "\n</tbody></table></div>"
    )


def render_html(board: Leaderboard, png: bytes | None) -> str:
    """``leaderboard.html`` as one string: no external resources, so it opens offline from any folder."""
    columns = board_columns(board)
    protocol = "".join(f"<dt>{_escape(k)}</dt><dd>{_escape(v)}</dd>" for k, v in _protocol_lines(board))
    parts = [
        f"<h1>{_title(board)}</h1>",
        f'<dl class="protocol">{protocol}</dl>',
        '<p class="meta">Inputs: ' + ", ".join(f"<code>{_escape(s)}</code>" for s in board.sources) + "</p>",
        "".join(f'<p class="meta">{_escape(text)}</p>' for text in _reading(board)),
        '<p class="meta">Click a column header to sort by it (best first); click again to reverse.</p>',
    ]
    for section in board.sections:
        notes = "".join(f"<li>{_escape(n)}</li>" for n in _section_notes(section, board))
        parts += [
            f'<h2 id="{_escape(section.setting)}">{_escape(setting_label(section.setting))} '
            f'<span class="meta">({_id_label(board)} <code>{_escape(section.protocol_id)}</code>)</span></h2>',
            _table(section, columns),
            f'<p class="basis">{_escape(section.basis)}</p><ul class="notes">{notes}</ul>',
        ]
    drawn = board_figure(board)
    if png is not None and drawn is not None:
        stem, title, caption = drawn
        data = base64.b64encode(png).decode("ascii")
        anchor = "pareto-front" if stem == FIGURE else stem.replace("_", "-")
        parts.append(
            f'<h2 id="{anchor}">{_escape(title)}</h2>'
            f'<figure id="{stem}"><img src="data:image/png;base64,{data}" alt="{_escape(title)}">'
            f"<figcaption>{html.escape(caption, quote=False)}</figcaption></figure>"
        )
    if board.notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{_escape(n)}</li>" for n in board.notes) + "</ul>")
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n<link rel="icon" href="data:,">\n'
        f"<title>{_title(board)} {_escape(board.board_id)}</title>\n<style>{CSS}</style>\n</head>\n"
        "<body>\n" + "\n".join(parts) + f"\n<script>{SCRIPT}</script>\n</body>\n</html>\n"
    )


def render_files(board: Leaderboard, formats: Sequence[str]) -> dict[str, bytes]:
    """The board's files by name: ``leaderboard.<format>`` for each format, and the Pareto
    figure (``pareto.png``, ``pareto.svg``; a suite board's performance profile,
    ``performance_profile.png``/``.svg``) with ``md`` or ``html``."""
    files: dict[str, bytes] = {}
    figure = None
    axes = pareto_axes(board.layout)
    if {"md", "html"} & set(formats) and board.suite is not None:
        figure = suite_profile_figure(board)
        files[f"{PROFILE}.png"], files[f"{PROFILE}.svg"] = figure["png"], figure["svg"]
    elif {"md", "html"} & set(formats) and axes is not None:
        points = pd.concat([s.ranked for s in board.sections], ignore_index=True)
        figure = pareto_figure(points, axes)
        files[f"{FIGURE}.png"], files[f"{FIGURE}.svg"] = figure["png"], figure["svg"]
    if "csv" in formats:
        files["leaderboard.csv"] = board.frame().to_csv(index=False, lineterminator="\n").encode()
    if "md" in formats:
        files["leaderboard.md"] = render_markdown(board, figure is not None).encode()
    if "html" in formats:
        files["leaderboard.html"] = render_html(board, figure["png"] if figure else None).encode()
    return files
