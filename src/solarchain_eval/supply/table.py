"""Load and validate a supply-chain dataset directory into a :class:`SupplyTable`.

Every problem is one :class:`~solarchain_eval.data.errors.DatasetError` naming the file, the
column and the first offending row. Without a directory, the default dataset (the builder's
default seed) is built once into the user cache, as the solar market's default is.
"""

from __future__ import annotations

import csv
import io
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..common.atomic_files import sha256_file
from ..data.default import cache_dir
from ..data.errors import DatasetError
from . import files as f

#: The cache key names the builder's seed and layout, so a changed default is a new directory.
DEFAULT_DATASET_NAME = f"supply-chain-v0-seed{f.DEFAULT_SEED}"

_MAX_UNITS = 1e9
_MAX_LEAD_DAYS = 60


@dataclass(frozen=True, eq=False)
class SupplyTable:
    """A validated dataset: per-region parameters (R,) and per-day inputs (D, R), regions alphabetical."""

    source: Path
    regions: tuple[str, ...]
    dates: tuple[str, ...]
    demand_mean_units: np.ndarray
    production_capacity_units: np.ndarray
    initial_stock_units: np.ndarray
    lead_time_days: np.ndarray
    spoilage_rate: np.ndarray
    warehouse_capacity_units: np.ndarray
    lane_capacity_units: np.ndarray
    orders_units: np.ndarray
    spoofed: np.ndarray
    reported_level_units: np.ndarray

    @property
    def days(self) -> int:
        return len(self.dates)

    @property
    def capacity_check_rate(self) -> np.ndarray:
        """Per day, the share of regions whose report exceeds the warehouse capacity (the raw check)."""
        over = self.spoofed & (self.reported_level_units > self.warehouse_capacity_units[None, :])
        return over.mean(axis=1)


def _rows(path: Path, columns: tuple[str, ...]) -> list[dict[str, str]]:
    if not path.is_file():
        raise DatasetError(path, "is missing (build the dataset with solarchain_eval.supply.build_supply_dataset)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise DatasetError(path, f"cannot be read as UTF-8 text ({error.__class__.__name__})") from None
    reader = csv.DictReader(io.StringIO(text))
    missing = [c for c in columns if c not in (reader.fieldnames or ())]
    if missing:
        raise DatasetError(path, f"missing column(s) {', '.join(missing)}", column=missing[0])
    rows = list(reader)
    for i, row in enumerate(rows):
        if any(row.get(c) is None for c in columns):
            raise DatasetError(path, "has fewer fields than the header", row=i)
    return rows


def _number(path: Path, row: dict[str, str], i: int, column: str, low: float, high: float) -> float:
    raw = row[column].strip()
    try:
        value = float(raw)
    except ValueError:
        raise DatasetError(path, f"'{raw}' is not a number", column=column, row=i) from None
    if not (np.isfinite(value) and low <= value <= high):
        raise DatasetError(path, f"{raw} is outside {low:g}..{high:g}", column=column, row=i)
    return value


def _per_day(path: Path, rows: list[dict[str, str]], regions: tuple[str, ...]) -> int:
    """Check the day-major layout (day 0..D-1, each with every region in order); returns D."""
    if not rows or len(rows) % len(regions):
        raise DatasetError(path, f"has {len(rows)} rows, not a whole number of days of {len(regions)} regions")
    for i, row in enumerate(rows):
        day, region = divmod(i, len(regions))
        if row["day"].strip() != str(day):
            raise DatasetError(path, f"expected day {day}, found '{row['day']}'", column="day", row=i)
        if row["region"].strip() != regions[region]:
            raise DatasetError(path, f"expected region '{regions[region]}', found '{row['region']}'", "region", i)
    return len(rows) // len(regions)


def load_supply_table(data_dir: Path | str) -> SupplyTable:
    """The validated dataset in ``data_dir`` (the three CSVs of :data:`~.files.SUPPLY_FILES`)."""
    root = Path(data_dir)
    if not root.is_dir():
        raise DatasetError(root, "is not a dataset directory")
    path = root / f.REGIONS_FILE
    region_rows = _rows(path, f.REGION_COLUMNS)
    regions = tuple(row["region"].strip() for row in region_rows)
    if regions != f.REGIONS:
        raise DatasetError(path, f"regions must be {', '.join(f.REGIONS)} in this order", column="region")
    bounds = {
        "demand_mean_units": (1e-6, _MAX_UNITS),
        "production_capacity_units": (0.0, _MAX_UNITS),
        "initial_stock_units": (0.0, _MAX_UNITS),
        "lead_time_days": (1, _MAX_LEAD_DAYS),
        "spoilage_rate_per_day": (0.0, 1.0),
        "warehouse_capacity_units": (0.0, _MAX_UNITS),
        "lane_capacity_units": (0.0, _MAX_UNITS),
    }
    params = {
        c: np.array([_number(path, row, i, c, *b) for i, row in enumerate(region_rows)]) for c, b in bounds.items()
    }
    for i, lead in enumerate(params["lead_time_days"]):
        if lead != int(lead):
            raise DatasetError(path, f"{lead} is not a whole number of days", column="lead_time_days", row=i)

    path = root / f.DEMAND_FILE
    demand_rows = _rows(path, ("day", "date", "region", "orders_units"))
    days = _per_day(path, demand_rows, regions)
    orders = np.array([_number(path, row, i, "orders_units", 0.0, _MAX_UNITS) for i, row in enumerate(demand_rows)])
    dates = tuple(row["date"].strip() for row in demand_rows[:: len(regions)])

    path = root / f.REPORTS_FILE
    report_rows = _rows(path, ("day", "region", "spoofed", "reported_level_units"))
    if _per_day(path, report_rows, regions) != days:
        raise DatasetError(path, f"covers {len(report_rows) // len(regions)} days, {f.DEMAND_FILE} {days}")
    spoofed = np.zeros(len(report_rows), dtype=bool)
    for i, row in enumerate(report_rows):
        if row["spoofed"].strip() not in ("0", "1"):
            raise DatasetError(path, f"'{row['spoofed']}' is not 0 or 1", column="spoofed", row=i)
        spoofed[i] = row["spoofed"].strip() == "1"
    level = np.array([_number(path, r, i, "reported_level_units", 0.0, _MAX_UNITS) for i, r in enumerate(report_rows)])
    shape = (days, len(regions))
    arrays: dict[str, Any] = {
        "orders_units": orders.reshape(shape),
        "spoofed": spoofed.reshape(shape),
        "reported_level_units": level.reshape(shape),
    }
    for value in (*params.values(), *arrays.values()):
        value.setflags(write=False)
    return SupplyTable(
        source=root,
        regions=regions,
        dates=dates,
        demand_mean_units=params["demand_mean_units"],
        production_capacity_units=params["production_capacity_units"],
        initial_stock_units=params["initial_stock_units"],
        lead_time_days=params["lead_time_days"].astype(np.int64),
        spoilage_rate=params["spoilage_rate_per_day"],
        warehouse_capacity_units=params["warehouse_capacity_units"],
        lane_capacity_units=params["lane_capacity_units"],
        **arrays,
    )


def default_supply_dir() -> Path:
    """The default dataset's directory, built there once (staged, then renamed into place)."""
    target = cache_dir() / "datasets" / DEFAULT_DATASET_NAME
    if (target / f.MANIFEST_FILE).is_file():
        return target
    from .build import build_supply_dataset

    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{DEFAULT_DATASET_NAME}.", dir=target.parent))
    try:
        build_supply_dataset(staging)
        try:
            os.rename(staging, target)
        except OSError:
            if not (target / f.MANIFEST_FILE).is_file():  # lost a race to a broken writer
                raise
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    return target


def supply_provenance(table: SupplyTable) -> dict[str, Any]:
    """``data_dir``, the sha256 of each dataset CSV and of the manifest when there is one."""
    root = Path(table.source)
    info: dict[str, Any] = {"data_dir": str(root.resolve()), "files": {}}
    for name in f.SUPPLY_FILES:
        if (root / name).is_file():
            info["files"][name] = sha256_file(root / name)
    if (root / f.MANIFEST_FILE).is_file():
        info["manifest_sha256"] = sha256_file(root / f.MANIFEST_FILE)
    return info
