"""Load and validate a dataset directory (the four CSVs of docs/dataset.md).

Every problem is reported as one :class:`DatasetError` naming the file, the column and the
first offending row (1-based data row; the file line is one more, for the header).
Only the columns the benchmark reads are required.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import DatasetError
from .files import GENERATION_FILE, MARKET_FILE, NODES_FILE, TRADES_FILE

VALID_STATUSES = ("verified", "rejected")

REQUIRED_COLUMNS = {
    NODES_FILE: ("node_id", "city"),
    GENERATION_FILE: ("timestamp", "node_id", "city", "P_max_W", "P_reported_W", "fdia_detected", "verification_status"),
    MARKET_FILE: ("timestamp", "total_verified_MW", "slippage_solarchain_pct"),
    TRADES_FILE: ("timestamp", "energy_purchased_MW"),
}


@dataclass(frozen=True)
class RawDataset:
    """The validated CSVs with parsed timestamps and an ``absolute_hour`` column."""

    root: Path
    nodes: pd.DataFrame
    generation: pd.DataFrame
    market: pd.DataFrame
    trades: pd.DataFrame
    first_timestamp: pd.Timestamp
    hours: int


def _read(root: Path, name: str) -> pd.DataFrame:
    path = root / name
    if not path.is_file():
        raise DatasetError(path, "file not found (a dataset needs " + ", ".join(REQUIRED_COLUMNS) + ")")
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, UnicodeDecodeError, pd.errors.EmptyDataError) as error:
        raise DatasetError(path, f"not a readable CSV file: {error}") from None
    missing = [c for c in REQUIRED_COLUMNS[name] if c not in frame.columns]
    if missing:
        raise DatasetError(path, f"missing column(s): {', '.join(missing)}", column=missing[0])
    return frame


def _first(mask: np.ndarray) -> int | None:
    hits = np.flatnonzero(mask)
    return int(hits[0]) if hits.size else None


def _numeric(frame: pd.DataFrame, path: Path, column: str, *, non_negative: bool, what: str = "power") -> np.ndarray:
    text = frame[column]
    values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=np.float64)
    bad = _first(~np.isfinite(values))
    if bad is not None:
        shown = text.iloc[bad]
        what = "empty" if shown.strip() == "" else f"'{shown}'"
        raise DatasetError(path, f"value is {what}, not a finite number", column, bad)
    if non_negative:
        bad = _first(values < 0)
        if bad is not None:
            raise DatasetError(path, f"negative value {float(values[bad])!r} ({what} cannot be negative)", column, bad)
    return values


def _timestamps(frame: pd.DataFrame, path: Path) -> pd.DatetimeIndex:
    text = frame["timestamp"]
    parsed = pd.to_datetime(text, format="ISO8601", errors="coerce", utc=True)
    bad = _first(parsed.isna().to_numpy())
    if bad is not None:
        raise DatasetError(path, f"'{text.iloc[bad]}' is not an ISO timestamp", "timestamp", bad)
    return pd.DatetimeIndex(parsed)


def _hours_since(stamps: pd.DatetimeIndex, first: pd.Timestamp) -> np.ndarray:
    return ((stamps - first) / pd.Timedelta(hours=1)).to_numpy(dtype=np.float64)


def _booleans(frame: pd.DataFrame, path: Path, column: str) -> np.ndarray:
    text = frame[column].str.strip().str.lower()
    known = text.isin(["true", "false", "1", "0"]).to_numpy()
    bad = _first(~known)
    if bad is not None:
        raise DatasetError(path, f"'{frame[column].iloc[bad]}' is not True or False", column, bad)
    return text.isin(["true", "1"]).to_numpy()


def load_raw_dataset(data_dir: str | Path) -> RawDataset:
    """Read and validate the four CSVs of a dataset directory."""
    root = Path(data_dir)
    if not root.is_dir():
        raise DatasetError(root, "dataset directory not found")
    nodes = _read(root, NODES_FILE)
    generation = _read(root, GENERATION_FILE)
    market = _read(root, MARKET_FILE)
    trades = _read(root, TRADES_FILE)

    nodes_path, gen_path = root / NODES_FILE, root / GENERATION_FILE
    market_path, trades_path = root / MARKET_FILE, root / TRADES_FILE

    duplicated = _first(nodes["node_id"].duplicated().to_numpy())
    if duplicated is not None:
        raise DatasetError(nodes_path, f"node '{nodes['node_id'].iloc[duplicated]}' is listed twice", "node_id", duplicated)
    if len(generation) == 0:
        raise DatasetError(gen_path, "the file has no data rows")

    # Generation rows.
    stamps = _timestamps(generation, gen_path)
    # Report times in the data's own UTC offset (that of its first record).
    first = stamps.min().tz_convert(pd.Timestamp(generation["timestamp"].iloc[0]).tzinfo)
    hours_float = _hours_since(stamps, first)
    bad = _first(hours_float != np.round(hours_float))
    if bad is not None:
        raise DatasetError(gen_path, f"'{generation['timestamp'].iloc[bad]}' is not on the hour", "timestamp", bad)
    absolute_hour = hours_float.astype(np.int64)
    p_max = _numeric(generation, gen_path, "P_max_W", non_negative=True)
    p_reported = _numeric(generation, gen_path, "P_reported_W", non_negative=True)
    fdia = _booleans(generation, gen_path, "fdia_detected")
    status = generation["verification_status"].str.strip()
    bad = _first(~status.isin(VALID_STATUSES).to_numpy())
    if bad is not None:
        raise DatasetError(
            gen_path,
            f"unknown verification status '{generation['verification_status'].iloc[bad]}' "
            f"(expected one of {', '.join(VALID_STATUSES)})",
            "verification_status",
            bad,
        )
    unknown = _first(~generation["node_id"].isin(nodes["node_id"]).to_numpy())
    if unknown is not None:
        raise DatasetError(
            gen_path, f"node '{generation['node_id'].iloc[unknown]}' is not in {NODES_FILE}", "node_id", unknown
        )
    duplicated = _first(pd.Series(list(zip(generation["node_id"], absolute_hour))).duplicated().to_numpy())
    if duplicated is not None:
        raise DatasetError(
            gen_path,
            f"duplicate record for node '{generation['node_id'].iloc[duplicated]}' at "
            f"{generation['timestamp'].iloc[duplicated]}",
            "timestamp",
            duplicated,
        )
    hours = int(absolute_hour.max()) + 1
    present = np.zeros(hours, dtype=bool)
    present[absolute_hour] = True
    if not present.all():
        gap = int(np.flatnonzero(~present)[0])
        raise DatasetError(
            gen_path, f"missing hour {(first + pd.Timedelta(hours=gap)).isoformat()} (no records at all)", "timestamp"
        )
    cities = sorted(generation["city"].unique())
    for city in cities:
        city_hours = np.zeros(hours, dtype=bool)
        city_hours[absolute_hour[(generation["city"] == city).to_numpy()]] = True
        if not city_hours.all():
            gap = int(np.flatnonzero(~city_hours)[0])
            raise DatasetError(
                gen_path,
                f"city '{city}' has no records at {(first + pd.Timedelta(hours=gap)).isoformat()} (missing hour)",
                "timestamp",
            )

    gen = pd.DataFrame(
        {
            "absolute_hour": absolute_hour,
            "node_id": generation["node_id"].to_numpy(),
            "city": generation["city"].to_numpy(),
            "P_max_W": p_max,
            "P_reported_W": p_reported,
            "fdia_detected": fdia,
            "verified": (status == "verified").to_numpy(),
        }
    )

    # Market rows: exactly one per hour of the window.
    market_stamps = _timestamps(market, market_path)
    market_hours = _hours_since(market_stamps, first)
    outside = _first((market_hours < 0) | (market_hours > hours - 1) | (market_hours != np.round(market_hours)))
    if outside is not None:
        raise DatasetError(
            market_path, f"timestamp {market['timestamp'].iloc[outside]} is outside the data window", "timestamp", outside
        )
    market_hours_int = market_hours.astype(np.int64)
    duplicated = _first(pd.Series(market_hours_int).duplicated().to_numpy())
    if duplicated is not None:
        raise DatasetError(market_path, f"hour {market['timestamp'].iloc[duplicated]} appears twice", "timestamp", duplicated)
    if len(market_hours_int) != hours:
        have = np.zeros(hours, dtype=bool)
        have[market_hours_int] = True
        gap = int(np.flatnonzero(~have)[0])
        raise DatasetError(market_path, f"missing hour {(first + pd.Timedelta(hours=gap)).isoformat()}", "timestamp")
    mkt = pd.DataFrame(
        {
            "absolute_hour": market_hours_int,
            "total_verified_MW": _numeric(market, market_path, "total_verified_MW", non_negative=True),
            "slippage_solarchain_pct": _numeric(
                market, market_path, "slippage_solarchain_pct", non_negative=True, what="slippage"
            ),
        }
    ).sort_values("absolute_hour", kind="stable")

    # Trades: inside the window, non-negative energy.
    if len(trades):
        trade_stamps = _timestamps(trades, trades_path)
        trade_hours = np.round(_hours_since(trade_stamps, first))
        outside = _first((trade_hours < 0) | (trade_hours > hours - 1))
        if outside is not None:
            last = (first + pd.Timedelta(hours=hours - 1)).isoformat()
            raise DatasetError(
                trades_path,
                f"trade at {trades['timestamp'].iloc[outside]} is outside the data window "
                f"[{first.isoformat()}, {last}]",
                "timestamp",
                outside,
            )
        energy = _numeric(trades, trades_path, "energy_purchased_MW", non_negative=True, what="energy")
    else:
        trade_hours, energy = np.zeros(0), np.zeros(0)
    trd = pd.DataFrame({"absolute_hour": trade_hours.astype(np.int64), "energy_purchased_MW": energy})

    return RawDataset(root=root, nodes=nodes, generation=gen, market=mkt, trades=trd, first_timestamp=first, hours=hours)
