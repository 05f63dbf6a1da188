"""The printed columns of a board's tables (Markdown and HTML): :class:`DisplayColumn` and the cell
renderers a task board (:func:`display_columns`) and a suite board share.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ...tasks.base import MetricSpec
from ..naming import policy_label
from ..table_model import fixed, pm, with_interval
from ..task_summary import metric_header
from .ranking import REFERENCE, REWARD, BoardLayout, board_layout


@dataclass(frozen=True)
class DisplayColumn:
    """A printed column of a board's table.

    Attributes
    ----------
    header : str
    key : str
        The ``leaderboard.csv`` column the HTML table sorts by.
    numeric : bool
        Sort as numbers (empty cells last) or as text.
    best : str
        ``"ascending"`` or ``"descending"``: the order a first click sorts in (best first).
    render : callable
        Row -> cell text.
    """

    header: str
    key: str
    numeric: bool
    best: str
    render: Callable[[dict[str, Any]], str]


def missing(value: Any) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


def _reward(digits: int, name: str = REWARD) -> Callable[[dict[str, Any]], str]:
    def render(row: dict[str, Any]) -> str:
        mean = row.get(f"{name}_mean")
        if row["row_kind"] == REFERENCE:  # published rows: mean ± std as the paper prints them
            std = row.get(f"{name}_std")
            if missing(mean):
                return "–"
            return pm(mean, std, digits) if not missing(std) else fixed(mean, digits)
        return with_interval(mean, row[f"{name}_low"], row[f"{name}_high"], digits)

    return render


def reference_interval(name: str, digits: int) -> Callable[[dict[str, Any]], str]:
    def render(row: dict[str, Any]) -> str:
        if row["row_kind"] == REFERENCE or missing(row.get(name)):
            return "–"
        return with_interval(row[name], row[f"{name}_low"], row[f"{name}_high"], digits)

    return render


def number(name: str, digits: int) -> Callable[[dict[str, Any]], str]:
    return lambda row: "–" if missing(row.get(name)) else fixed(row[name], digits)


def rank_cell(row: dict[str, Any]) -> str:
    return "paper" if row["row_kind"] == REFERENCE else str(int(row["rank"]))


def shown_policy(layout: BoardLayout, policy: str) -> str:
    """A policy's name on the board: the report's label, except that a task's own baseline is not
    marked as a user agent (the report's labels know the solar market's baselines only)."""
    if layout.paper is None and policy in layout.baselines:
        return policy
    return policy_label(policy)


#: The order a first click on a metric's header sorts in (best first), by its declared direction.
_BEST = {"higher": "descending", "lower": "ascending", "none": "ascending"}


def _metric_column(layout: BoardLayout, spec: MetricSpec) -> DisplayColumn:
    """A shown metric's column: the paper's header where it has one, else ``name (unit) arrow``."""
    key = f"{spec.name}_mean"
    return DisplayColumn(layout.label(spec) or metric_header(spec), key, True, _BEST[spec.direction], number(key, 4))


def display_columns(confidence: float, layout: BoardLayout | None = None) -> list[DisplayColumn]:
    """The printed columns of every board table (Markdown and HTML) of ``layout``'s task (default: solar)."""
    layout = layout or board_layout()
    level = f"{confidence:.0%}"
    name = layout.ranked.name
    ranked = layout.label(layout.ranked) or metric_header(layout.ranked)
    return [
        DisplayColumn("Rank", "rank", True, "ascending", rank_cell),
        DisplayColumn("Policy", "policy", False, "ascending", lambda r: shown_policy(layout, str(r["policy"]))),
        DisplayColumn("Access", "access", False, "ascending", lambda r: str(r["access"]) or "–"),
        DisplayColumn("Source", "source", False, "ascending", lambda r: str(r["source"])),
        DisplayColumn("Episodes", "episodes", True, "descending", number("episodes", 0)),
        DisplayColumn(f"Mean {ranked} [{level} CI]", f"{name}_mean", True, "descending", _reward(2, name)),
        DisplayColumn(
            f"IQM {ranked} [{level} CI]", f"{name}_iqm", True, "descending", reference_interval(f"{name}_iqm", 2)
        ),
        DisplayColumn(
            f"P(> best baseline) [{level} CI]",
            "p_improvement",
            True,
            "descending",
            reference_interval("p_improvement", 2),
        ),
        *(_metric_column(layout, spec) for spec in layout.shown),
    ]
