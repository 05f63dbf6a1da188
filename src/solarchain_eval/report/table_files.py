"""Reading a run's table files for the report: CSV (or its Parquet twin) and JSON, checked column by
column so that an error names the file, column and row at fault.

:mod:`.loading` reads a run directory or paper root through these; each returns a frame whose
older column names are upgraded (records_schema's version history).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..evaluation.records import PARQUET_TWINS
from ..experiments.layout import COMBINED_DIR, run_table_paths
from ..records_schema import upgrade_columns
from .naming import SETTINGS
from .options import ReportDataError


def read_table_file(path: Path, required: tuple[str, ...]) -> pd.DataFrame:
    """A CSV table, or its Parquet twin (``evaluate --step-format parquet``) by its suffix."""
    if path.suffix == ".parquet":
        frame = read_parquet_file(path)
    else:
        try:
            frame = pd.read_csv(path)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
            raise ReportDataError(f"{path}: not a readable CSV ({error})") from None
    # Files written before a column was renamed or removed (records_schema's version history).
    upgrade = upgrade_columns(list(frame.columns))
    if upgrade:
        frame = frame.drop(columns=[c for c, new in upgrade.items() if new is None])
        frame = frame.rename(columns={c: new for c, new in upgrade.items() if new is not None})
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise ReportDataError(f"{path}: missing column(s) {', '.join(missing)}")
    return frame


def read_parquet_file(path: Path) -> pd.DataFrame:
    import pyarrow as pa

    try:
        return pd.read_parquet(path)
    except (pa.ArrowException, OSError, ValueError) as error:
        raise ReportDataError(f"{path}: not a readable Parquet file ({error})") from None


def check_numeric(frame: pd.DataFrame, columns: tuple[str, ...], path: Path) -> None:
    for column in columns:
        if not pd.api.types.is_numeric_dtype(frame[column]):
            values = pd.to_numeric(frame[column], errors="coerce")
            bad = int(np.flatnonzero(values.isna() & frame[column].notna())[0])
            raise ReportDataError(
                f"{path}: column {column} row {bad + 2} holds {frame[column].iloc[bad]!r}, not a number"
            )


def check_settings(frame: pd.DataFrame, path: Path, kind: str) -> None:
    unknown = sorted(set(frame["setting"].astype(str)) - set(SETTINGS))
    if unknown:
        row = int(np.flatnonzero(frame["setting"].astype(str) == unknown[0])[0])
        raise ReportDataError(
            f"{path}: row {row + 2} has setting {unknown[0]!r} (expected one of {', '.join(SETTINGS)})"
        )
    if kind == "paper" and path.parent.parent.name == COMBINED_DIR:
        other = sorted(set(frame["setting"]) - {path.parent.name})
        if other:
            raise ReportDataError(f"{path}: holds setting {other[0]!r} but lies in the folder of {path.parent.name!r}")


def read_tables(
    root: Path, name: str, required: tuple[str, ...], kind: str, numeric: tuple[str, ...] = ()
) -> tuple[pd.DataFrame, list[Path]]:
    paths = run_table_paths(root, name)
    if name in PARQUET_TWINS:
        paths += run_table_paths(root, PARQUET_TWINS[name])
    frames = []
    for path in paths:
        frame = read_table_file(path, required)
        check_settings(frame, path, kind)
        check_numeric(frame, numeric, path)
        frames.append(frame)
    if not frames:
        return pd.DataFrame(columns=list(required)), []
    return pd.concat(frames, ignore_index=True), paths


def read_json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise ReportDataError(f"{path}: not valid JSON ({error.msg} at line {error.lineno})") from None
