"""The hourly benchmark table (docs/dataset.md#hourly-table): numpy arrays derived once from a dataset directory.

Everything the environment reads per step lives here as plain arrays indexed by absolute
hour (and city). The sums follow the original release's order of addition: per-(city, hour)
sums with pandas' group-by (compensated summation), then numpy's reduction across the cities
in alphabetical order, so per-step values agree with it bit for bit.
"""

from __future__ import annotations

import hashlib
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .files import DATASET_FILES
from .load import RawDataset, check_dataset_dir, load_raw_dataset


@dataclass(frozen=True, eq=False)
class HourlyTable:
    """Hour-level market inputs.

    Attributes
    ----------
    cities : tuple of str
        City names, alphabetical (the order of every per-city axis).
    first_timestamp : str
        ISO timestamp of absolute hour 0.
    verified_mwh, reported_mwh, pmax_mwh, excess_mwh, rejected_mwh : ndarray, shape (H,)
        Verified, reported, physical-maximum, above-P_max and violating (rejected) energy, MWh.
    raw_violation_rate : ndarray, shape (H,)
        ν, the fraction of records with a physics violation or FDIA label.
    demand_mwh : ndarray, shape (H,)
        Q, the hour's P2P trade demand (0 where no trades), MWh.
    static_slippage : ndarray, shape (H,)
        σ, the market file's ``slippage_solarchain_pct``.
    total_verified_mw : ndarray, shape (H,)
        The market file's ``total_verified_MW`` (clearing-demand fallback).
    city_verified_w : ndarray, shape (H, C)
        Verified power per city, W.
    city_violation_rate : ndarray, shape (H, C)
        Violation rate per city.
    verified_w : ndarray, shape (H,)
        Verified power summed over cities, W.
    """

    source: str
    fingerprint: str
    cities: tuple[str, ...]
    first_timestamp: str
    verified_mwh: np.ndarray
    reported_mwh: np.ndarray
    pmax_mwh: np.ndarray
    excess_mwh: np.ndarray
    rejected_mwh: np.ndarray
    raw_violation_rate: np.ndarray
    demand_mwh: np.ndarray
    static_slippage: np.ndarray
    total_verified_mw: np.ndarray
    city_verified_w: np.ndarray
    city_violation_rate: np.ndarray
    verified_w: np.ndarray

    @property
    def hours(self) -> int:
        return int(self.verified_mwh.shape[0])

    def __post_init__(self) -> None:
        for value in vars(self).values():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)


def _row_sums(matrix: np.ndarray) -> np.ndarray:
    # numpy's 1-D reduction order per row (what pandas' Series.sum does on the city rows).
    return np.array([np.add.reduce(row) for row in matrix], dtype=np.float64)


def table_from_raw(raw: RawDataset, fingerprint: str = "") -> HourlyTable:
    gen = raw.generation
    p_rep, p_max = gen["P_reported_W"].to_numpy(), gen["P_max_W"].to_numpy()
    excess = np.maximum(p_rep - p_max, 0.0)
    violation = (excess > 1e-6) | gen["fdia_detected"].to_numpy()
    frame = pd.DataFrame(
        {
            "city": gen["city"].to_numpy(),
            "absolute_hour": gen["absolute_hour"].to_numpy(),
            "verified_W": np.where(gen["verified"].to_numpy(), p_rep, 0.0),
            "reported_W": p_rep,
            "pmax_W": p_max,
            "excess_W": excess,
            "rejected_W": np.where(violation, p_rep, 0.0),
            "violations": violation.astype(np.int64),
            "records": np.ones(len(gen), dtype=np.int64),
        }
    )
    per_city_hour = frame.groupby(["city", "absolute_hour"], sort=True).sum()
    cities = tuple(sorted(frame["city"].unique()))
    hours = raw.hours

    def matrix(column: str, dtype=np.float64) -> np.ndarray:
        wide = per_city_hour[column].unstack("city").reindex(index=range(hours), columns=list(cities))
        return np.ascontiguousarray(wide.to_numpy(dtype=dtype))

    city_verified = matrix("verified_W")
    city_violations, city_records = matrix("violations", np.int64), matrix("records", np.int64)
    verified_w = _row_sums(city_verified)

    demand = np.zeros(hours)
    trade_hours = raw.trades["absolute_hour"].to_numpy()
    trade_energy = raw.trades["energy_purchased_MW"].to_numpy()
    for hour in np.unique(trade_hours):
        demand[hour] = np.add.reduce(trade_energy[trade_hours == hour])  # file order

    market_hours = raw.market["absolute_hour"].to_numpy()
    static_slippage = np.zeros(hours)
    static_slippage[market_hours] = raw.market["slippage_solarchain_pct"].to_numpy()
    total_verified_mw = np.zeros(hours)
    total_verified_mw[market_hours] = raw.market["total_verified_MW"].to_numpy()

    return HourlyTable(
        source=str(raw.root),
        fingerprint=fingerprint,
        cities=cities,
        first_timestamp=raw.first_timestamp.isoformat(),
        verified_mwh=verified_w / 1_000_000.0,
        reported_mwh=_row_sums(matrix("reported_W")) / 1_000_000.0,
        pmax_mwh=_row_sums(matrix("pmax_W")) / 1_000_000.0,
        excess_mwh=_row_sums(matrix("excess_W")) / 1_000_000.0,
        rejected_mwh=_row_sums(matrix("rejected_W")) / 1_000_000.0,
        raw_violation_rate=city_violations.sum(axis=1) / np.maximum(city_records.sum(axis=1), 1),
        demand_mwh=demand,
        static_slippage=static_slippage,
        total_verified_mw=total_verified_mw,
        city_verified_w=city_verified,
        city_violation_rate=city_violations / np.maximum(city_records, 1),
        verified_w=verified_w,
    )


def dataset_fingerprint(data_dir: str | Path) -> str:
    """sha256 over the four CSVs' names, sizes and modification times (cheap change detection)."""
    digest = hashlib.sha256()
    root = Path(data_dir).resolve()
    digest.update(str(root).encode())
    for name in DATASET_FILES:
        path = root / name
        try:
            stat = os.stat(path)
            digest.update(f"{name}:{stat.st_size}:{stat.st_mtime_ns}".encode())
        except OSError:  # unreadable or missing: load_raw_dataset names the problem
            digest.update(f"{name}:missing".encode())
    return digest.hexdigest()


_CACHE: dict[str, HourlyTable] = {}
_LOCK = threading.Lock()


def load_table(data_dir: str | Path) -> HourlyTable:
    """Load, validate and derive the hourly table of ``data_dir``, once per process.

    Later calls for an unchanged directory return the same (read-only) object.
    """
    fingerprint = dataset_fingerprint(check_dataset_dir(data_dir))
    with _LOCK:
        cached = _CACHE.get(fingerprint)
    if cached is not None:
        return cached
    table = table_from_raw(load_raw_dataset(data_dir), fingerprint)
    with _LOCK:
        _CACHE[fingerprint] = table
    return table
