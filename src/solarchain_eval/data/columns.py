"""Parsing one column of a dataset CSV, as :mod:`.load` reads it: every cell checked, the first bad
one named (file, column, 1-based data row) in a :class:`~.errors.DatasetError`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import DatasetError

# An ISO date and time that ends in a UTC offset ("Z", "+08:00", "-0500").
_HAS_OFFSET = re.compile(r"^\s*\d{4}-\d{2}-\d{2}[T ].*(?:Z|[+-]\d{2}:?\d{2})\s*$")


def first_true(mask: np.ndarray) -> int | None:
    """The index of the first true entry of ``mask`` (None: none is)."""
    hits = np.flatnonzero(mask)
    return int(hits[0]) if hits.size else None


def numeric_column(frame: pd.DataFrame, path: Path, column: str, *, maximum: float, what: str) -> np.ndarray:
    """A non-negative finite column, at most ``maximum`` (a plausibility ceiling in the column's unit)."""
    text = frame[column]
    values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=np.float64)
    bad = first_true(~np.isfinite(values))
    if bad is not None:
        shown = text.iloc[bad]
        shown = "empty" if shown.strip() == "" else f"'{shown}'"
        raise DatasetError(path, f"value is {shown}, not a finite number", column, bad)
    bad = first_true(values < 0)
    if bad is not None:
        raise DatasetError(path, f"negative value {float(values[bad])!r} ({what} cannot be negative)", column, bad)
    bad = first_true(values > maximum)
    if bad is not None:
        raise DatasetError(
            path, f"value {float(values[bad])!r} is implausibly large ({what} above {maximum:g})", column, bad
        )
    return values


def timestamp_column(frame: pd.DataFrame, path: Path) -> pd.DatetimeIndex:
    """The ``timestamp`` column parsed: ISO times, each with its UTC offset."""
    text = frame["timestamp"]
    parsed = pd.to_datetime(text, format="ISO8601", errors="coerce", utc=True)
    unparsed = parsed.isna().to_numpy()
    naive = ~text.str.match(_HAS_OFFSET).to_numpy()
    bad = first_true(unparsed | naive)
    if bad is not None:
        if unparsed[bad]:
            raise DatasetError(path, f"'{text.iloc[bad]}' is not an ISO timestamp", "timestamp", bad)
        raise DatasetError(
            path,
            f"'{text.iloc[bad]}' has no UTC offset (a naive time is ambiguous; write e.g. 2026-04-01T00:00:00+08:00)",
            "timestamp",
            bad,
        )
    return pd.DatetimeIndex(parsed)


def whole_hours(stamps: pd.DatetimeIndex, first: pd.Timestamp, frame: pd.DataFrame, path: Path) -> np.ndarray:
    """Whole hours since ``first``; a time between two hours is an error, never rounded."""
    hours = ((stamps - first) / pd.Timedelta(hours=1)).to_numpy(dtype=np.float64)
    bad = first_true(hours != np.round(hours))
    if bad is not None:
        raise DatasetError(path, f"'{frame['timestamp'].iloc[bad]}' is not on the hour", "timestamp", bad)
    return hours.astype(np.int64)


def boolean_column(frame: pd.DataFrame, path: Path, column: str) -> np.ndarray:
    """A True/False column (``true``, ``false``, ``1``, ``0``, any case)."""
    text = frame[column].str.strip().str.lower()
    known = text.isin(["true", "false", "1", "0"]).to_numpy()
    bad = first_true(~known)
    if bad is not None:
        raise DatasetError(path, f"'{frame[column].iloc[bad]}' is not True or False", column, bad)
    return text.isin(["true", "1"]).to_numpy()
