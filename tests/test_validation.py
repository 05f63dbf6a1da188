"""Invalid datasets: one clear error naming the file, column and first offending row."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.data.load import DatasetError, load_raw_dataset

GEN = "spatiotemporal_generation.csv"


def _mutated(src: Path, dst: Path, name: str, change: Callable[[pd.DataFrame], pd.DataFrame]) -> Path:
    shutil.copytree(src, dst)
    frame = pd.read_csv(dst / name, dtype=str, keep_default_na=False)
    change(frame).to_csv(dst / name, index=False)
    return dst


def _set(row: int, column: str, value: str) -> Callable[[pd.DataFrame], pd.DataFrame]:
    def change(frame: pd.DataFrame) -> pd.DataFrame:
        frame.loc[row, column] = value
        return frame

    return change


CASES = {
    "non-numeric power": (
        GEN,
        _set(40, "P_reported_W", "12,5"),
        r"column 'P_reported_W', row 41 \(line 42\): value is '12,5', not a finite number",
    ),
    "empty power": (
        GEN,
        _set(7, "P_max_W", ""),
        r"column 'P_max_W', row 8 \(line 9\): value is empty, not a finite number",
    ),
    "NaN power": (
        GEN,
        _set(9, "P_reported_W", "nan"),
        r"column 'P_reported_W', row 10 \(line 11\): value is 'nan', not a finite number",
    ),
    "negative power": (
        GEN,
        _set(3, "P_reported_W", "-5.0"),
        r"column 'P_reported_W', row 4 \(line 5\): negative value -5.0",
    ),
    "unknown status": (
        GEN,
        _set(11, "verification_status", "pending"),
        r"column 'verification_status', row 12 \(line 13\): unknown verification status 'pending'",
    ),
    "bad FDIA flag": (
        GEN,
        _set(2, "fdia_detected", "maybe"),
        r"column 'fdia_detected', row 3 \(line 4\): 'maybe' is not True or False",
    ),
    "bad timestamp": (
        GEN,
        _set(5, "timestamp", "yesterday"),
        r"column 'timestamp', row 6 \(line 7\): 'yesterday' is not an ISO timestamp",
    ),
    "duplicate record": (
        GEN,
        lambda f: pd.concat([f, f.iloc[[20]]], ignore_index=True),
        r"column 'timestamp', row 1153 \(line 1154\): duplicate record for node 'WUH-001' at 2026-06-01T20:00:00\+08:00",
    ),
    "missing hour": (
        GEN,
        lambda f: f[f["timestamp"] != "2026-06-02T05:00:00+08:00"],
        r"column 'timestamp': missing hour 2026-06-02T05:00:00\+08:00 \(no records at all\)",
    ),
    "city missing an hour": (
        GEN,
        lambda f: f[~((f["city"] == "Xian") & (f["timestamp"] == "2026-06-03T10:00:00+08:00"))],
        r"city 'Xian' has no records at 2026-06-03T10:00:00\+08:00",
    ),
    "missing column": (GEN, lambda f: f.drop(columns=["P_max_W"]), r"column 'P_max_W': missing column\(s\): P_max_W"),
    "trade outside window": (
        "p2p_trades.csv",
        _set(0, "timestamp", "2026-07-01T10:00:00+08:00"),
        r"p2p_trades.csv, column 'timestamp', row 1 \(line 2\): trade at 2026-07-01T10:00:00\+08:00 is outside the data window",
    ),
    "negative demand": (
        "p2p_trades.csv",
        _set(2, "energy_purchased_MW", "-0.1"),
        r"column 'energy_purchased_MW', row 3 \(line 4\): negative value",
    ),
    "market hour missing": (
        "market_liquidity.csv",
        lambda f: f.drop(index=30),
        r"market_liquidity.csv, column 'timestamp': missing hour 2026-06-02T06:00:00\+08:00",
    ),
    "unknown node": (
        GEN,
        _set(0, "node_id", "ZZZ-999"),
        r"column 'node_id', row 1 \(line 2\): node 'ZZZ-999' is not in urban_energy_nodes.csv",
    ),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_invalid_dataset_error_names_file_column_and_row(tiny_dataset, tmp_path, case):
    name, change, message = CASES[case]
    data = _mutated(tiny_dataset, tmp_path / "ds", name, change)
    with pytest.raises(DatasetError, match=message) as info:
        load_raw_dataset(data)
    assert name in str(info.value)


def test_missing_file_is_named(tiny_dataset, tmp_path):
    shutil.copytree(tiny_dataset, tmp_path / "ds")
    (tmp_path / "ds" / "p2p_trades.csv").unlink()
    with pytest.raises(DatasetError, match=r"p2p_trades.csv: file not found"):
        load_raw_dataset(tmp_path / "ds")


def test_data_check_and_evaluate_exit_2_and_write_nothing(tiny_dataset, tmp_path):
    data = _mutated(tiny_dataset, tmp_path / "ds", GEN, _set(9, "P_reported_W", "nan"))
    runner = CliRunner()
    check = runner.invoke(app, ["data", "check", str(data)])
    assert check.exit_code == 2
    assert "column 'P_reported_W', row 10" in check.output
    run_dir = tmp_path / "run"
    result = runner.invoke(
        app, ["evaluate", "--data", str(data), "--episodes", "1", "--seeds", "1", "--out", str(run_dir)]
    )
    assert result.exit_code == 2
    assert "P_reported_W" in result.output
    assert not run_dir.exists()


def test_data_check_accepts_a_valid_dataset(tiny_dataset):
    result = CliRunner().invoke(app, ["data", "check", str(tiny_dataset)])
    assert result.exit_code == 0, result.output
    assert "Kunming, Wuhan, Xian" in result.output
    assert "1,152" in result.output  # 12 nodes × 96 hours


def _bytes_changed(src: Path, dst: Path, name: str, change: Callable[[bytes], bytes]) -> Path:
    shutil.copytree(src, dst)
    (dst / name).write_bytes(change((dst / name).read_bytes()))
    return dst


def _in_line(line: int, at: int, inserted: bytes) -> Callable[[bytes], bytes]:
    """Insert ``inserted`` ``at`` bytes into file line ``line`` (1-based)."""

    def change(raw: bytes) -> bytes:
        lines = raw.split(b"\n")
        lines[line - 1] = lines[line - 1][:at] + inserted + lines[line - 1][at:]
        return b"\n".join(lines)

    return change


NODE_ID_AT = len("2026-06-01T00:00:00+08:00,0,")  # a generation row's node_id, after its timestamp and hour

CONTROL_CASES = {
    "NUL in a node id": (GEN, _in_line(2, NODE_ID_AT, b"\x00\x00"), r"line 2: NUL byte \(0x00\) at character 29"),
    "NUL in the header": (GEN, _in_line(1, 0, b"\x00"), r"line 1: NUL byte \(0x00\) at character 1"),
    "NUL run in a value": (
        "market_liquidity.csv",
        _in_line(7, 30, b"\x00" * 8),
        r"line 7: NUL byte \(0x00\) at character 31",
    ),
    "escape character": ("p2p_trades.csv", _in_line(3, 4, b"\x1b[0m"), r"line 3: control character 0x1b"),
    "NUL after CRLF lines": (
        GEN,
        lambda raw: _in_line(4, 2, b"\x00")(raw).replace(b"\n", b"\r\n"),
        r"line 4: NUL byte \(0x00\) at character 3",
    ),
}


@pytest.mark.parametrize("case", sorted(CONTROL_CASES))
def test_control_characters_are_named_at_their_line(tiny_dataset, tmp_path, case):
    name, change, message = CONTROL_CASES[case]
    data = _bytes_changed(tiny_dataset, tmp_path / "ds", name, change)
    with pytest.raises(DatasetError, match=rf"{name}: {message}"):
        load_raw_dataset(data)
    check = CliRunner().invoke(app, ["data", "check", str(data)])
    text = check.output.strip()
    assert check.exit_code == 2, text
    assert len(text.splitlines()) == 1 and "\x00" not in text and "\x1b" not in text, repr(text)
    assert name in text and "line " in text and "not in urban_energy_nodes.csv" not in text, repr(text)


def test_tabs_and_quoted_newlines_are_not_control_characters(tiny_dataset, tmp_path):
    data = _mutated(tiny_dataset, tmp_path / "ds", "urban_energy_nodes.csv", lambda f: f.assign(note="a\tb\nc"))
    load_raw_dataset(data)  # no error
