"""Load and validate a dataset directory (the four CSVs; see docs/dataset.md).

Every problem is reported as one :class:`DatasetError` naming the file, the column and the
first offending row (1-based data row; the file line is one more, for the header).
Only the columns the benchmark reads are required; the checks refuse anything that would
silently change the results (a gap, a contradiction, a value rounded or summed into overflow).
"""

from __future__ import annotations

import csv
import errno
import io
import re
import stat
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .columns import boolean_column, first_true, numeric_column, timestamp_column, whole_hours
from .errors import DatasetError
from .files import GENERATION_FILE, MARKET_FILE, NODES_FILE, TRADES_FILE

VALID_STATUSES = ("verified", "rejected")

REQUIRED_COLUMNS = {
    NODES_FILE: ("node_id", "city"),
    GENERATION_FILE: (
        "timestamp",
        "node_id",
        "city",
        "P_max_W",
        "P_reported_W",
        "fdia_detected",
        "verification_status",
    ),
    MARKET_FILE: ("timestamp", "total_verified_MW", "slippage_solarchain_pct"),
    TRADES_FILE: ("timestamp", "energy_purchased_MW"),
}

# Plausibility ceilings: far above any real reading, yet low enough that a month of sums stays finite.
MAX_NODE_POWER_W = 1e9  # 1 GW, more than any single solar plant
MAX_MARKET_MW = 1e6
MAX_SLIPPAGE_PCT = 100.0

# Control characters, which no CSV text holds: C0 but tab, LF and CR; DEL; C1.
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f]")
_LINE_BREAK = re.compile(r"\r\n|\r|\n")


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


# --- files -------------------------------------------------------------------------------------
def _os_problem(error: OSError) -> str:
    if isinstance(error, IsADirectoryError):
        return "is a directory, not a file"
    if isinstance(error, PermissionError):
        return "permission denied (this user cannot read it)"
    if isinstance(error, FileNotFoundError):
        return "not found"
    if error.errno == errno.ELOOP:
        return "is a symbolic link loop (it never resolves to a real path)"
    return f"cannot be read: {error.strerror or error}"


def check_dataset_dir(data_dir: str | Path) -> Path:
    """The dataset directory as a path, or a :class:`DatasetError` saying why it is not one."""
    root = Path(data_dir)
    try:
        mode = root.stat().st_mode
    except OSError as error:
        problem = "dataset directory not found" if isinstance(error, FileNotFoundError) else _os_problem(error)
        raise DatasetError(root, problem) from None
    if not stat.S_ISDIR(mode):
        raise DatasetError(root, "is a file, not a dataset directory (give the folder that holds the four CSVs)")
    return root


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    """Header and data rows of a UTF-8 CSV file (a byte-order mark is allowed); blank lines skipped."""
    try:
        raw = path.read_bytes()
    except OSError as error:
        problem = _os_problem(error)
        if isinstance(error, FileNotFoundError):
            problem = "file not found (a dataset needs " + ", ".join(REQUIRED_COLUMNS) + ")"
        raise DatasetError(path, problem) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise DatasetError(path, f"not UTF-8 text (byte {raw[error.start]:#04x} at offset {error.start})") from None
    _check_no_control_characters(path, text)
    try:
        records = [row for row in csv.reader(io.StringIO(text, newline="")) if row]
    except csv.Error as error:
        raise DatasetError(path, f"not a readable CSV file: {error}") from None
    if not records:
        raise DatasetError(path, "the file is empty (no header line)")
    return records[0], records[1:]


def _check_no_control_characters(path: Path, text: str) -> None:
    """Refuse a NUL byte or other control character, named at its file line and character.

    Checked before parsing: read as data, it would reach a check that shows it as part of a value
    (an "unknown node" with invisible characters), or pass unseen in a column the benchmark skips.
    """
    found = _CONTROL.search(text)
    if found is None:
        return
    at = found.start()
    breaks = list(_LINE_BREAK.finditer(text, 0, at))
    line, start = len(breaks) + 1, (breaks[-1].end() if breaks else 0)
    code = ord(found.group())
    what = "NUL byte (0x00)" if code == 0 else f"control character {code:#04x}"
    raise DatasetError(
        path,
        f"line {line}: {what} at character {at - start + 1} (a dataset CSV holds text only; is the file corrupted?)",
    )


def _read(root: Path, name: str) -> pd.DataFrame:
    path = root / name
    header, rows = _rows(path)
    seen: set[str] = set()
    for column in header:
        if column in seen:
            raise DatasetError(path, "the column name appears twice in the header", column=column)
        seen.add(column)
    missing = [c for c in REQUIRED_COLUMNS[name] if c not in seen]
    if missing:
        raise DatasetError(path, f"missing column(s): {', '.join(missing)}", column=missing[0])
    for index, row in enumerate(rows):
        if len(row) != len(header):
            column = header[min(len(row), len(header) - 1)]
            raise DatasetError(
                path,
                f"the row has {len(row)} fields, the header {len(header)} (a truncated or malformed line)",
                column,
                index,
            )
    return pd.DataFrame(rows, columns=header, dtype=str)


# --- generation --------------------------------------------------------------------------------
def _data_window(generation: pd.DataFrame, path: Path) -> tuple[pd.Timestamp, np.ndarray]:
    """The first hour (in the data's own UTC offset, that of its first record) and each row's hour."""
    if len(generation) == 0:
        raise DatasetError(path, "the file has no data rows")
    stamps = timestamp_column(generation, path)
    earliest = int(np.argmin(stamps.asi8))
    first = stamps[earliest].tz_convert(pd.Timestamp(generation["timestamp"].iloc[0]).tzinfo)
    if first != first.normalize():
        # Hour of day is counted from the first hour, so a 06:00 start would make 06:00 "hour 0".
        raise DatasetError(
            path, f"the data starts at {first.isoformat()}, not at local midnight", "timestamp", earliest
        )
    return first, whole_hours(stamps, first, generation, path)


def _check_nodes(nodes: pd.DataFrame, generation: pd.DataFrame, nodes_path: Path, gen_path: Path) -> None:
    """Every generation row names a listed node in that node's city; every node has records."""
    duplicated = first_true(nodes["node_id"].duplicated().to_numpy())
    if duplicated is not None:
        raise DatasetError(
            nodes_path, f"node '{nodes['node_id'].iloc[duplicated]}' is listed twice", "node_id", duplicated
        )
    unknown = first_true(~generation["node_id"].isin(nodes["node_id"]).to_numpy())
    if unknown is not None:
        raise DatasetError(
            gen_path, f"node '{generation['node_id'].iloc[unknown]}' is not in {NODES_FILE}", "node_id", unknown
        )
    absent = first_true(~nodes["node_id"].isin(generation["node_id"]).to_numpy())
    if absent is not None:
        raise DatasetError(
            nodes_path, f"node '{nodes['node_id'].iloc[absent]}' has no records in {GENERATION_FILE}", "node_id", absent
        )
    listed_city = generation["node_id"].map(nodes.set_index("node_id")["city"])
    contradicts = (generation["city"] != listed_city).to_numpy()
    if not contradicts.any():
        return
    by_node = pd.DataFrame({"node": generation["node_id"], "bad": contradicts, "city": generation["city"]}).groupby(
        "node"
    )
    # A node whose rows all agree on another city: the nodes file is the one at fault.
    wrong_in_nodes_file = by_node["bad"].all() & (by_node["city"].nunique() == 1)
    blamed = first_true(nodes["node_id"].map(wrong_in_nodes_file).fillna(False).to_numpy(dtype=bool))
    if blamed is not None:
        node = nodes["node_id"].iloc[blamed]
        other = generation["city"][generation["node_id"] == node].iloc[0]
        raise DatasetError(
            nodes_path,
            f"node '{node}' is in city '{nodes['city'].iloc[blamed]}' here but in '{other}' in {GENERATION_FILE}",
            "city",
            blamed,
        )
    row = first_true(contradicts)
    raise DatasetError(
        gen_path,
        f"city '{generation['city'].iloc[row]}' contradicts node '{generation['node_id'].iloc[row]}''s city "
        f"'{listed_city.iloc[row]}' in {NODES_FILE}",
        "city",
        row,
    )


def _first_gap(hours_present: np.ndarray, hours: int) -> int | None:
    present = np.zeros(hours, dtype=bool)
    present[hours_present] = True
    return first_true(~present)


def _check_coverage(generation: pd.DataFrame, absolute_hour: np.ndarray, first: pd.Timestamp, path: Path) -> int:
    """One record per node and hour over the whole window; returns the number of hours."""
    keys = pd.DataFrame({"node": generation["node_id"].to_numpy(), "hour": absolute_hour})
    duplicated = first_true(keys.duplicated().to_numpy())
    if duplicated is not None:
        raise DatasetError(
            path,
            f"duplicate record for node '{generation['node_id'].iloc[duplicated]}' at "
            f"{generation['timestamp'].iloc[duplicated]}",
            "timestamp",
            duplicated,
        )
    hours = int(absolute_hour.max()) + 1

    def when(hour: int) -> str:
        return (first + pd.Timedelta(hours=hour)).isoformat()

    gap = _first_gap(absolute_hour, hours)
    if gap is not None:
        raise DatasetError(path, f"missing hour {when(gap)} (no records at all)", "timestamp")
    for column, what in (("city", "city"), ("node_id", "node")):
        for name, group in keys.groupby(generation[column].to_numpy(), sort=True):
            gap = _first_gap(group["hour"].to_numpy(), hours)
            if gap is not None:
                raise DatasetError(path, f"{what} '{name}' has no records at {when(gap)} (missing hour)", "timestamp")
    return hours


def _generation_table(generation: pd.DataFrame, absolute_hour: np.ndarray, path: Path) -> pd.DataFrame:
    p_max = numeric_column(generation, path, "P_max_W", maximum=MAX_NODE_POWER_W, what="power, W,")
    p_reported = numeric_column(generation, path, "P_reported_W", maximum=MAX_NODE_POWER_W, what="power, W,")
    fdia = boolean_column(generation, path, "fdia_detected")
    status = generation["verification_status"].str.strip()
    bad = first_true(~status.isin(VALID_STATUSES).to_numpy())
    if bad is not None:
        raise DatasetError(
            path,
            f"unknown verification status '{generation['verification_status'].iloc[bad]}' "
            f"(expected one of {', '.join(VALID_STATUSES)})",
            "verification_status",
            bad,
        )
    return pd.DataFrame(
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


# --- market and trades -------------------------------------------------------------------------
def _market_table(market: pd.DataFrame, first: pd.Timestamp, hours: int, path: Path) -> pd.DataFrame:
    """Exactly one market row per hour of the window."""
    market_hours = whole_hours(timestamp_column(market, path), first, market, path)
    outside = first_true((market_hours < 0) | (market_hours > hours - 1))
    if outside is not None:
        raise DatasetError(
            path, f"timestamp {market['timestamp'].iloc[outside]} is outside the data window", "timestamp", outside
        )
    duplicated = first_true(pd.Series(market_hours).duplicated().to_numpy())
    if duplicated is not None:
        raise DatasetError(path, f"hour {market['timestamp'].iloc[duplicated]} appears twice", "timestamp", duplicated)
    gap = _first_gap(market_hours, hours)
    if gap is not None:
        raise DatasetError(path, f"missing hour {(first + pd.Timedelta(hours=gap)).isoformat()}", "timestamp")
    return pd.DataFrame(
        {
            "absolute_hour": market_hours,
            "total_verified_MW": numeric_column(
                market, path, "total_verified_MW", maximum=MAX_MARKET_MW, what="power, MW,"
            ),
            "slippage_solarchain_pct": numeric_column(
                market, path, "slippage_solarchain_pct", maximum=MAX_SLIPPAGE_PCT, what="slippage, %,"
            ),
        }
    ).sort_values("absolute_hour", kind="stable")


def _trades_table(trades: pd.DataFrame, first: pd.Timestamp, hours: int, path: Path) -> pd.DataFrame:
    """Trades on the hour inside the window, non-negative energy."""
    if len(trades) == 0:
        return pd.DataFrame({"absolute_hour": np.zeros(0, dtype=np.int64), "energy_purchased_MW": np.zeros(0)})
    trade_hours = whole_hours(timestamp_column(trades, path), first, trades, path)
    outside = first_true((trade_hours < 0) | (trade_hours > hours - 1))
    if outside is not None:
        last = (first + pd.Timedelta(hours=hours - 1)).isoformat()
        raise DatasetError(
            path,
            f"trade at {trades['timestamp'].iloc[outside]} is outside the data window [{first.isoformat()}, {last}]",
            "timestamp",
            outside,
        )
    energy = numeric_column(trades, path, "energy_purchased_MW", maximum=MAX_MARKET_MW, what="energy, MWh,")
    return pd.DataFrame({"absolute_hour": trade_hours, "energy_purchased_MW": energy})


def load_raw_dataset(data_dir: str | Path) -> RawDataset:
    """Read and validate the four CSVs of a dataset directory.

    Parameters
    ----------
    data_dir : str or Path
        The dataset directory.

    Returns
    -------
    RawDataset
        The validated tables, each row tagged with its ``absolute_hour``.

    Raises
    ------
    DatasetError
        On the first problem found, naming the file, column and row.
    """
    root = check_dataset_dir(data_dir)
    nodes, generation = _read(root, NODES_FILE), _read(root, GENERATION_FILE)
    market, trades = _read(root, MARKET_FILE), _read(root, TRADES_FILE)
    gen_path = root / GENERATION_FILE

    first, absolute_hour = _data_window(generation, gen_path)
    gen = _generation_table(generation, absolute_hour, gen_path)
    _check_nodes(nodes, generation, root / NODES_FILE, gen_path)
    hours = _check_coverage(generation, absolute_hour, first, gen_path)
    mkt = _market_table(market, first, hours, root / MARKET_FILE)
    trd = _trades_table(trades, first, hours, root / TRADES_FILE)
    return RawDataset(
        root=root, nodes=nodes, generation=gen, market=mkt, trades=trd, first_timestamp=first, hours=hours
    )
