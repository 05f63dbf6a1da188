"""The supply-chain market's dataset builder: the :class:`~solarchain_eval.tasks.dataset.ScenarioDatasetBuilder`
that ``sweep`` reaches through the task (``SUPPLY_TASK.dataset``).

It wraps :func:`~.build.build_supply_dataset`: a seed, a date range (``start`` to the day before
``end``) and the phantom-stock scenario (rate, ``uniform`` / ``clustered`` / ``stealthy``
pattern, severity, burst length in days) give the same files byte for byte. The market has five
fixed regions and no weather, so it is not a full :class:`~solarchain_eval.tasks.dataset.DatasetBuilder`
(no cities, nodes, weather sources, splits or families; ``data`` builds the solar market's datasets).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..data.fdia import DEFAULT_BURST_HOURS, DEFAULT_FDIA_PATTERN, FDIA_FRACTION, FdiaScenario, scenario_from_knobs
from ..tasks.dataset import SCENARIO_PARAMETERS, BuildDefaults, FalseDataKnobs
from . import files as f
from .build import MAX_DAYS, build_supply_dataset
from .table import load_supply_table

_START = dt.date.fromisoformat(f.DEFAULT_START)
#: The default build: seed 20260511, 364 days from Monday 2024-01-01 (``end`` is the day after the last).
SUPPLY_BUILD_DEFAULTS = BuildDefaults(
    f.DEFAULT_SEED, f.DEFAULT_START, (_START + dt.timedelta(days=f.DEFAULT_DAYS)).isoformat(), None, None
)
#: The phantom-stock patterns on the (day, region) report records (docs/tasks/supply_chain.md#attack-scenarios).
SUPPLY_PATTERN_LINES = {
    "uniform": "report records drawn uniformly.",
    "clustered": "bursts of {burst_hours} consecutive days in one region.",
    "stealthy": "reports at min(m, 1) x warehouse capacity, invisible to the capacity check.",
}
SUPPLY_FALSE_DATA = FalseDataKnobs(SUPPLY_PATTERN_LINES, DEFAULT_FDIA_PATTERN, FDIA_FRACTION, DEFAULT_BURST_HOURS)


def supply_days(start: str, end: str) -> int:
    """Days from ``start`` to the day before ``end`` (``ValueError``: a bad date or range)."""
    try:
        first, stop = dt.date.fromisoformat(start), dt.date.fromisoformat(end)
    except (TypeError, ValueError):
        raise ValueError(f"start {start!r} and end {end!r} must be dates YYYY-MM-DD") from None
    days = (stop - first).days
    if not 1 <= days <= MAX_DAYS:
        raise ValueError(f"end {end} must be 1 to {MAX_DAYS} days after start {start}")
    return days


@dataclass(frozen=True)
class SupplyDataset:
    """The supply-chain market's dataset builder (see the module docstring); use :data:`SUPPLY_DATASET`."""

    files: tuple[str, ...] = f.SUPPLY_FILES
    manifest: str = f.MANIFEST_FILE
    defaults: BuildDefaults = SUPPLY_BUILD_DEFAULTS
    false_data: FalseDataKnobs = SUPPLY_FALSE_DATA
    #: A seed, a date range and the scenario: no cities, nodes, time zone or weather.
    parameters: tuple[str, ...] = SCENARIO_PARAMETERS

    def scenario(self, rate: float, severity: str | None, pattern: str, burst_hours: int) -> FdiaScenario:
        return scenario_from_knobs(rate, severity, pattern, burst_hours)

    def build_point(self, out: Path, parameters: Mapping[str, Any]) -> dict[str, Any]:
        p = parameters
        days = supply_days(p["start"], p["end"])
        scenario = self.scenario(p["fdia_rate"], p["fdia_severity"], p["fdia_pattern"], p["fdia_burst_hours"])
        return build_supply_dataset(out, seed=p["seed"], days=days, start=p["start"], fdia=scenario)

    def check(self, data_dir: Path) -> tuple[tuple[str, str], ...]:
        table = load_supply_table(data_dir)
        return (
            ("days", f"{table.days:,} from {table.dates[0]}"),
            ("regions", ", ".join(table.regions)),
            ("report records", f"{table.spoofed.size:,}"),
            ("spoofed reports", f"{int(table.spoofed.sum()):,}"),
            ("over capacity", f"{int((table.capacity_check_rate * len(table.regions)).round().sum()):,}"),
        )


#: The supply-chain market's dataset builder (``SUPPLY_TASK.dataset``).
SUPPLY_DATASET = SupplyDataset()
