"""The paper's published results, stored once as data (``paper_reference.json``).

Every number of the paper's result tables (the main table, the physics-ablation deltas, the
Planner/Auditor effects and the appendix tables), a few numbers its text states, and its
findings. Each value carries where it is printed (table label, row labels, column header, which
number of the cell), the printed string, the number, its printed decimals, and what it measures
in this package's terms: ``setting`` (and ``base_setting`` for a paired delta, treated minus
base), ``policy`` (``"ppo+sac+dqn"`` for rows that pool policies), ``metric`` (a ``metrics.csv``
or ``actions.csv`` column), ``statistic`` and the column of the report table that regenerates it
(``report_column``). The tests re-read every value from the paper's LaTeX source.

A finding names the cells it compares (``cells``, value ids) and the comparison (``kind``):

``beats``
    every policy in ``policies`` is better than every policy in ``than`` (``better`` says
    whether higher or lower is better for the metric);
``extreme``
    the one policy in ``policies`` has the ``max``/``min`` value among itself and ``than``;
``not_better``
    no policy in ``policies`` is clearly better than those in ``than``;
``sign``
    each policy's paired delta has the sign in ``signs`` (``"+"`` or ``"-"``);
``within`` / ``above``
    each policy's value lies within the stated bounds / above the stated bound (``bounds``,
    value ids of the numbers the text states).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from importlib import resources
from typing import Any

import pandas as pd

REFERENCE_FILE = "paper_reference.json"
#: Policies of the pooled rows (``"ppo+sac+dqn"``) are joined with this.
POOL_SEPARATOR = "+"
FINDING_KINDS = ("beats", "extreme", "not_better", "sign", "within", "above")


@dataclass(frozen=True)
class PaperTable:
    """One result table of the paper: its label, the caption's first sentence, the report table that
    regenerates it (``report_key``), its row-label columns and its data columns (as printed)."""

    label: str
    caption: str
    report_key: str
    label_columns: tuple[str, ...]
    columns: tuple[str, ...]


@dataclass(frozen=True)
class Ref:
    """What a number measures: the estimate of ``statistic`` of ``metric`` for ``policy`` in ``setting``
    (a paired delta ``setting`` minus ``base_setting`` when that is set)."""

    setting: str
    base_setting: str | None
    policy: str
    metric: str
    statistic: str

    @property
    def policies(self) -> tuple[str, ...]:
        """The policies behind the number (several for a pooled row)."""
        return tuple(self.policy.split(POOL_SEPARATOR))


@dataclass(frozen=True)
class Finding:
    """A finding the paper states, the cells it compares and how (see the module docstring)."""

    id: str
    source: str
    statement: str
    kind: str
    setting: str
    base_setting: str | None
    metric: str
    statistic: str
    policies: tuple[str, ...]
    than: tuple[str, ...]
    cells: tuple[str, ...]
    extreme: str | None = None
    signs: dict[str, str] | None = None
    bounds: tuple[str, ...] = ()

    def ref(self, policy: str) -> Ref:
        """The quantity of ``policy`` this finding compares."""
        return Ref(self.setting, self.base_setting, policy, self.metric, self.statistic)

    @property
    def compared(self) -> tuple[str, ...]:
        """Every policy (or pooled row) the finding reads, ``policies`` first."""
        return (*self.policies, *self.than)


@cache
def _document() -> dict[str, Any]:
    text = resources.files(__package__).joinpath(REFERENCE_FILE).read_text(encoding="utf-8")
    return json.loads(text)


def paper_values() -> pd.DataFrame:
    """Every stored value, one row each (a fresh copy).

    Columns: ``id``, ``source`` ("table" or "text"), ``table`` (LaTeX label of the table, or of
    the section whose text states the number), ``row`` (tuple of the row's label cells),
    ``column`` (the header as printed in LaTeX), ``part`` ("mean", "std", "min", "max", "p05",
    "p95" or "value": which number of the cell), ``printed``, ``value``, ``decimals``,
    ``setting``, ``base_setting``, ``policy``, ``metric``, ``statistic``, ``level`` ("episode" or
    "step"), ``report_column``, ``unit`` ("percent" for percentages in the text) and
    ``context`` (the text around a number stated in the text).
    """
    return _values_frame().copy()


@cache
def _values_frame() -> pd.DataFrame:
    # object columns keep None as None (a text dtype would turn it into NaN)
    frame = pd.DataFrame(list(_values_by_id().values()), dtype=object)
    frame["value"] = frame["value"].astype(float)
    frame["decimals"] = frame["decimals"].astype(int)
    return frame


@cache
def _values_by_id() -> dict[str, dict[str, Any]]:
    document = _document()
    rows = (dict(zip(document["value_fields"], values, strict=True)) for values in document["values"])
    return {row["id"]: {**row, "row": tuple(row["row"])} for row in rows}


def paper_value(value_id: str) -> dict[str, Any]:
    """One stored value by id (a copy); raises KeyError for an unknown id."""
    return dict(_values_by_id()[value_id])


def as_fraction(value_id: str) -> float:
    """A stored number as a fraction: percentages of the text are divided by 100."""
    row = _values_by_id()[value_id]
    return row["value"] / 100.0 if row["unit"] == "percent" else row["value"]


def fraction_decimals(value_id: str) -> int:
    """Printed decimals of a stored number as a fraction (a percentage's plus two)."""
    row = _values_by_id()[value_id]
    return row["decimals"] + (2 if row["unit"] == "percent" else 0)


def ref_of(value_id: str) -> Ref:
    """What a stored value measures."""
    row = _values_by_id()[value_id]
    return Ref(row["setting"], row["base_setting"], row["policy"], row["metric"], row["statistic"])


def paper_tables() -> list[PaperTable]:
    """The paper's result tables in the order the paper prints them (body first, then appendix)."""
    return [
        PaperTable(t["label"], t["caption"], t["report_key"], tuple(t["label_columns"]), tuple(t["columns"]))
        for t in _document()["tables"]
    ]


def paper_findings() -> list[Finding]:
    """The paper's findings, in the order its text states them."""
    return [
        Finding(
            id=f["id"],
            source=f["source"],
            statement=f["statement"],
            kind=f["kind"],
            setting=f["setting"],
            base_setting=f["base_setting"],
            metric=f["metric"],
            statistic=f["statistic"],
            policies=tuple(f["policies"]),
            than=tuple(f["than"]),
            cells=tuple(f["cells"]),
            extreme=f["extreme"],
            signs=dict(f["signs"]) if f["signs"] else None,
            bounds=tuple(f["bounds"]),
        )
        for f in _document()["findings"]
    ]


def metric_better() -> dict[str, str]:
    """For each main-table metric, whether "higher" or "lower" is better (the main table's caption)."""
    return dict(_document()["better"])


def table_values(label: str, part: str | None = None) -> pd.DataFrame:
    """The stored values of one table (label ``tab:...``), optionally one part ("mean", "std", ...)."""
    frame = paper_values()
    frame = frame[frame["table"] == label]
    return (frame if part is None else frame[frame["part"] == part]).reset_index(drop=True)


#: How the paper prints a cell of several numbers, by its parts.
_CELL_FORMS = {
    ("mean", "std"): "{mean} $\\pm$ {std}",
    ("mean", "p05", "p95"): "{mean} ({p05}--{p95})",
    ("min", "max"): "{min}--{max}",
    ("value",): "{value}",
}


def printed_row(label: str, row: tuple[str, ...]) -> list[str]:
    """The data cells of one row of a table as the paper's LaTeX prints them (e.g. ``-23.38 $\\pm$ 0.80``).

    ``row`` is the row's label cells, e.g. ``("Static",)`` or ``("RL", "PPO")``.
    """
    table = next(t for t in paper_tables() if t.label == label)
    values = table_values(label)
    values = values[values["row"] == tuple(row)]
    if values.empty:
        raise KeyError(f"{label} has no row {row!r}")
    cells = []
    for column in table.columns:
        parts = values[values["column"] == column]
        printed = dict(zip(parts["part"], parts["printed"], strict=True))
        cells.append(_CELL_FORMS[tuple(printed)].format(**printed))
    return cells


def paper_findings_values(finding: Finding) -> dict[Ref, float]:
    """The paper's number for each quantity a finding compares (from the cells it names)."""
    out: dict[Ref, float] = {}
    for value_id in finding.cells:
        ref = ref_of(value_id)
        if ref.policy is not None and value_id not in finding.bounds:
            out[ref] = as_fraction(value_id)
    return out


__all__ = [
    "FINDING_KINDS",
    "Finding",
    "PaperTable",
    "REFERENCE_FILE",
    "Ref",
    "as_fraction",
    "fraction_decimals",
    "metric_better",
    "paper_findings",
    "paper_findings_values",
    "paper_tables",
    "paper_value",
    "paper_values",
    "printed_row",
    "ref_of",
    "table_values",
]
