"""Fuzzing the dataset loader with mutations of the published dataset (rebuilt from the packaged weather).

Two families: harmless rewritings (BOM, CRLF, column order, extra columns, the same instants in
another UTC offset) must give a bit-identical hourly table; corruptions must be refused by
``data check`` with exit 2 and one line naming the file and the column. Fixed budget, derandomized.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.data.files import DATASET_FILES, GENERATION_FILE, MARKET_FILE, NODES_FILE, TRADES_FILE
from solarchain_eval.data.load import load_raw_dataset
from solarchain_eval.data.table import table_from_raw

FUZZ = settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large],
)
TIMED = (GENERATION_FILE, MARKET_FILE, TRADES_FILE)
NUMERIC = {
    GENERATION_FILE: ("P_max_W", "P_reported_W"),
    MARKET_FILE: ("total_verified_MW", "slippage_solarchain_pct"),
    TRADES_FILE: ("energy_purchased_MW",),
}
OFFSETS = [dt.timedelta(0), dt.timedelta(hours=-5), dt.timedelta(hours=5, minutes=30), dt.timedelta(hours=14)]


@dataclass
class Csv:
    header: list[str]
    rows: list[list[str]]

    def column(self, name: str) -> int:
        return self.header.index(name)

    def copy(self) -> Csv:
        return Csv(list(self.header), [list(row) for row in self.rows])

    def text(self, newline: str = "\n") -> str:
        return "".join(",".join(row) + newline for row in [self.header, *self.rows])


@dataclass
class Source:
    root: Path
    files: dict[str, Csv]
    table: object


@pytest.fixture(scope="module")
def source(published_dir) -> Source:
    root = published_dir
    files = {}
    for name in DATASET_FILES:
        text = (root / name).read_text(encoding="utf-8")
        records = list(csv.reader(io.StringIO(text, newline="")))
        files[name] = Csv(records[0], records[1:])
        assert files[name].text() == text, f"{name} does not round-trip through the fuzzer's writer"
    return Source(root, files, table_from_raw(load_raw_dataset(root)))


@contextmanager
def _written(files: dict[str, Csv], *, crlf: frozenset = frozenset(), bom: frozenset = frozenset()) -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="solarchain-fuzz-") as folder:
        root = Path(folder)
        for name, table in files.items():
            text = ("\ufeff" if name in bom else "") + table.text("\r\n" if name in crlf else "\n")
            (root / name).write_bytes(text.encode("utf-8"))
        yield root


def _tables_equal(a, b) -> None:
    for field in fields(a):
        if field.name in ("source", "fingerprint"):
            continue
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), field.name
        else:
            assert x == y, field.name


# --- harmless -------------------------------------------------------------------------------
@st.composite
def harmless(draw, files: dict[str, Csv]):
    out = {name: table.copy() for name, table in files.items()}
    for name in draw(st.sets(st.sampled_from(DATASET_FILES))):  # column order
        table = out[name]
        order = draw(st.permutations(range(len(table.header))))
        out[name] = Csv([table.header[i] for i in order], [[row[i] for i in order] for row in table.rows])
    for name in draw(st.sets(st.sampled_from(DATASET_FILES))):  # an extra column
        table = out[name]
        at = draw(st.integers(0, len(table.header)))
        table.header.insert(at, "note")
        for row in table.rows:
            row.insert(at, "x")
    for name in draw(st.sets(st.sampled_from(TIMED))):  # the same instants in another UTC offset
        table, offset = out[name], dt.timezone(draw(st.sampled_from(OFFSETS)))
        column = table.column("timestamp")
        skip = 1 if name == GENERATION_FILE else 0  # the first record's offset is the data's local time
        stamps = pd.to_datetime(pd.Series([row[column] for row in table.rows[skip:]]), utc=True)
        rewritten = stamps.dt.tz_convert(offset).dt.strftime("%Y-%m-%dT%H:%M:%S%z")
        for row, stamp in zip(table.rows[skip:], rewritten, strict=True):
            row[column] = stamp
    crlf = frozenset(draw(st.sets(st.sampled_from(DATASET_FILES))))
    bom = frozenset(draw(st.sets(st.sampled_from(DATASET_FILES))))
    return out, crlf, bom


@FUZZ
@given(data=st.data())
def test_harmless_mutations_give_the_same_table(source, data):
    files, crlf, bom = data.draw(harmless(source.files))
    with _written(files, crlf=crlf, bom=bom) as root:
        _tables_equal(table_from_raw(load_raw_dataset(root)), source.table)


# --- corruptions ----------------------------------------------------------------------------
def _set_cell(files, name, row, column, value):
    table = files[name]
    table.rows[row][table.column(column)] = value
    return name, column


KINDS = ["value", "missing row", "duplicate row", "city", "node city", "naive", "off hour", "truncated"]


@st.composite
def corruption(draw, files: dict[str, Csv], kind: str):
    out = {name: table.copy() for name, table in files.items()}
    if kind == "value":
        name = draw(st.sampled_from(sorted(NUMERIC)))
        column = draw(st.sampled_from(NUMERIC[name]))
        value = draw(
            st.sampled_from(["abc", "1,5", "", "nan", "NaN", "inf", "-inf", "-1.5", "-0.001", "1e300", "1e10"])
        )
        row = draw(st.integers(0, len(out[name].rows) - 1))
        return out, _set_cell(out, name, row, column, value)
    if kind in ("missing row", "duplicate row"):
        name = draw(st.sampled_from([GENERATION_FILE, MARKET_FILE]))
        rows = out[name].rows
        row = draw(st.integers(0, len(rows) - 1))
        if kind == "missing row":
            del rows[row]
        else:
            rows.insert(draw(st.integers(0, len(rows))), list(rows[row]))
        return out, (name, "timestamp")
    if kind == "city":
        table = out[GENERATION_FILE]
        row = draw(st.integers(0, len(table.rows) - 1))
        own = table.rows[row][table.column("city")]
        cities = sorted({r[1] for r in out[NODES_FILE].rows} - {own})
        return out, _set_cell(out, GENERATION_FILE, row, "city", draw(st.sampled_from(cities)))
    if kind == "node city":
        table = out[NODES_FILE]
        row = draw(st.integers(0, len(table.rows) - 1))
        own = table.rows[row][table.column("city")]
        cities = sorted({r[table.column("city")] for r in table.rows} - {own})
        return out, _set_cell(out, NODES_FILE, row, "city", draw(st.sampled_from(cities)))
    if kind in ("naive", "off hour"):
        name = draw(st.sampled_from(TIMED))
        table = out[name]
        row = draw(st.integers(0, len(table.rows) - 1))
        stamp = table.rows[row][table.column("timestamp")]
        value = stamp[:19] if kind == "naive" else stamp[:14] + draw(st.sampled_from(["30", "01", "59"])) + stamp[16:]
        return out, _set_cell(out, name, row, "timestamp", value)
    # Truncated: the file ends inside its last line, at least one field short.
    name = draw(st.sampled_from(DATASET_FILES))
    last = ",".join(out[name].rows[-1])
    cut = draw(st.integers(0, last.rfind(",")))
    out[name].rows[-1] = last[:cut].split(",")
    return out, (name, None)


@pytest.mark.parametrize("kind", KINDS)
@settings(FUZZ, max_examples=4)
@given(data=st.data())
def test_corruptions_are_refused_naming_file_and_column(source, kind, data):
    files, (name, column) = data.draw(corruption(source.files, kind))
    with _written(files) as root:
        result = CliRunner().invoke(app, ["data", "check", str(root)])
    message = result.output.strip()
    assert result.exit_code == 2, message
    assert len(message.splitlines()) == 1 and "Traceback" not in message, message
    assert name in message and ("column '" in message if column is None else f"column '{column}'" in message), message
