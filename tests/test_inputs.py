"""Bad inputs that used to crash or pass silently: each is one line naming what and where, exit 2."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import atomic_write_json
from solarchain_eval.config import BenchmarkConfig, ConfigError, load_config
from solarchain_eval.data.load import DatasetError, load_raw_dataset
from solarchain_eval.envs.env import SolarChainEnv

GEN, NODES, MARKET, TRADES = (
    "spatiotemporal_generation.csv",
    "urban_energy_nodes.csv",
    "market_liquidity.csv",
    "p2p_trades.csv",
)


def _copy(src: Path, dst: Path, name: str, change: Callable[[pd.DataFrame], pd.DataFrame]) -> Path:
    shutil.copytree(src, dst)
    frame = pd.read_csv(dst / name, dtype=str, keep_default_na=False)
    change(frame).to_csv(dst / name, index=False)
    return dst


def _set(row: int, column: str, value: str) -> Callable[[pd.DataFrame], pd.DataFrame]:
    def change(frame: pd.DataFrame) -> pd.DataFrame:
        frame.loc[row, column] = value
        return frame

    return change


def _drop_first_hours(frame: pd.DataFrame) -> pd.DataFrame:
    return frame[~frame["timestamp"].str.contains("2026-06-01T0[0-5]")]


# Tiny dataset: 12 nodes (Wuhan, Xian, Kunming; 4 each) × 96 hours, node-major, from 2026-06-01T00:00+08:00.
DATASET_CASES = {
    "naive timestamp is blamed on its own row": (
        GEN,
        _set(5, "timestamp", "2026-06-01T05:00:00"),
        r"column 'timestamp', row 6 \(line 7\): '2026-06-01T05:00:00' has no UTC offset",
    ),
    "naive first timestamp": (
        GEN,
        _set(0, "timestamp", "2026-06-01T00:00:00"),
        r"column 'timestamp', row 1 \(line 2\): '2026-06-01T00:00:00' has no UTC offset",
    ),
    "first hour not local midnight": (
        GEN,
        _drop_first_hours,
        r"column 'timestamp', row 1 \(line 2\): the data starts at 2026-06-01T06:00:00\+08:00, not at local midnight",
    ),
    "node missing one hour": (
        GEN,
        lambda f: f.drop(index=96 + 17),
        r"column 'timestamp': node 'WUH-002' has no records at 2026-06-01T17:00:00\+08:00",
    ),
    "generation city contradicts its node": (
        GEN,
        _set(40, "city", "Xian"),
        r"spatiotemporal_generation.csv, column 'city', row 41 \(line 42\): city 'Xian' contradicts node 'WUH-001'",
    ),
    "nodes-file city contradicts the generation file": (
        NODES,
        _set(1, "city", "Kunming"),
        r"urban_energy_nodes.csv, column 'city', row 2 \(line 3\): node 'WUH-002' is in city 'Kunming' here but in 'Wuhan'",
    ),
    "node without records": (
        NODES,
        lambda f: pd.concat([f, f.iloc[[0]].assign(node_id="WUH-999")], ignore_index=True),
        r"urban_energy_nodes.csv, column 'node_id', row 13 \(line 14\): node 'WUH-999' has no records",
    ),
    "trade not on the hour": (
        TRADES,
        _set(1, "timestamp", "2026-06-01T07:30:00+08:00"),
        r"p2p_trades.csv, column 'timestamp', row 2 \(line 3\): '2026-06-01T07:30:00\+08:00' is not on the hour",
    ),
    "trade before the window": (
        TRADES,
        _set(0, "timestamp", "2026-05-31T23:00:00+08:00"),
        r"p2p_trades.csv, column 'timestamp', row 1 \(line 2\): trade at 2026-05-31T23:00:00\+08:00 is outside",
    ),
    "trade a few minutes before the window": (
        TRADES,
        _set(0, "timestamp", "2026-05-31T23:40:00+08:00"),
        r"p2p_trades.csv, column 'timestamp', row 1 \(line 2\): '2026-05-31T23:40:00\+08:00' is not on the hour",
    ),
    "market row not on the hour": (
        MARKET,
        _set(3, "timestamp", "2026-06-01T03:15:00+08:00"),
        r"market_liquidity.csv, column 'timestamp', row 4 \(line 5\): '2026-06-01T03:15:00\+08:00' is not on the hour",
    ),
    "reading of 1e300": (
        GEN,
        _set(30, "P_reported_W", "1e300"),
        r"column 'P_reported_W', row 31 \(line 32\): value 1e\+300 is implausibly large",
    ),
    "demand of 1e300": (
        TRADES,
        _set(2, "energy_purchased_MW", "1e300"),
        r"column 'energy_purchased_MW', row 3 \(line 4\): value 1e\+300 is implausibly large",
    ),
}


@pytest.mark.parametrize("case", sorted(DATASET_CASES))
def test_dataset_problems_are_named(tiny_dataset, tmp_path, case):
    name, change, message = DATASET_CASES[case]
    data = _copy(tiny_dataset, tmp_path / "ds", name, change)
    with pytest.raises(DatasetError, match=message):
        load_raw_dataset(data)


def _evaluate(data: Path, out: Path, *extra: str):
    args = ["evaluate", "--data", str(data), "--policies", "static", "--episodes", "1", "--seeds", "1"]
    return CliRunner().invoke(app, [*args, "--out", str(out), *extra])


def _assert_refused(result, *needles: str) -> None:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    message = result.output.strip()
    assert len(message.splitlines()) == 1, message
    for needle in needles:
        assert needle in message, message


@pytest.mark.parametrize(
    "case", ["naive timestamp is blamed on its own row", "node missing one hour", "reading of 1e300"]
)
def test_evaluate_refuses_bad_datasets_with_exit_2_and_writes_nothing(tiny_dataset, tmp_path, case):
    name, change, _ = DATASET_CASES[case]
    data = _copy(tiny_dataset, tmp_path / "ds", name, change)
    result = _evaluate(data, tmp_path / "run")
    _assert_refused(result, name)
    assert not (tmp_path / "run").exists()


def test_header_problems(tiny_dataset, tmp_path):
    shutil.copytree(tiny_dataset, tmp_path / "ds")
    path = tmp_path / "ds" / GEN
    text = path.read_text()
    path.write_text(text.replace("irradiance_Wm2", "P_max_W", 1))
    with pytest.raises(DatasetError, match=r"column 'P_max_W': the column name appears twice"):
        load_raw_dataset(tmp_path / "ds")
    # A truncated file: the last line loses its final fields.
    path.write_text(text[: text.rstrip("\n").rfind(",", 0, len(text) - 30)])
    with pytest.raises(DatasetError, match=r"row 1152 \(line 1153\): the row has \d+ fields, the header 12"):
        load_raw_dataset(tmp_path / "ds")
    path.write_bytes(text.encode().replace(b"Wuhan", b"Wuh\xe4n", 1))
    with pytest.raises(DatasetError, match=r"spatiotemporal_generation.csv: not UTF-8 text \(byte 0xe4"):
        load_raw_dataset(tmp_path / "ds")


@contextmanager
def _unprivileged() -> Iterator[None]:
    """Run as user ``nobody`` when the tests run as root (root reads a mode-000 file anyway)."""
    if os.geteuid() != 0:
        yield
        return
    os.seteuid(65534)
    try:
        yield
    finally:
        os.seteuid(0)


@pytest.fixture
def public_copy(tiny_dataset) -> Iterator[Path]:
    """A copy of the tiny dataset that user ``nobody`` can reach (pytest's own folders are private)."""
    parent = Path(tempfile.mkdtemp(prefix="solarchain-inputs-"))
    try:
        parent.chmod(0o755)
        data = parent / "ds"
        shutil.copytree(tiny_dataset, data)
        data.chmod(0o755)
        for path in data.iterdir():
            path.chmod(0o644)
        yield data
    finally:
        shutil.rmtree(parent)


def test_unreadable_paths_are_named_not_called_missing(tiny_dataset, public_copy, tmp_path):
    data = public_copy
    load_raw_dataset(data)  # loads lazily imported modules while their files are still readable
    (data / MARKET).chmod(0o000)
    with _unprivileged(), pytest.raises(DatasetError, match=r"market_liquidity.csv: permission denied"):
        load_raw_dataset(data)
    (data / MARKET).chmod(0o644)

    (data / TRADES).unlink()
    (data / TRADES).mkdir()
    with pytest.raises(DatasetError, match=r"p2p_trades.csv: is a directory, not a file"):
        load_raw_dataset(data)
    (data / TRADES).rmdir()
    os.symlink(data / "loop-b", data / TRADES)
    os.symlink(data / TRADES, data / "loop-b")
    with pytest.raises(DatasetError, match=r"p2p_trades.csv: is a symbolic link loop"):
        load_raw_dataset(data)

    loop = tmp_path / "loop"
    os.symlink(tmp_path / "loop2", loop)
    os.symlink(loop, tmp_path / "loop2")
    _assert_refused(_evaluate(loop, tmp_path / "run"), "symbolic link loop")
    _assert_refused(_evaluate(tiny_dataset / GEN, tmp_path / "run"), "is a file, not a dataset directory")
    assert not (tmp_path / "run").exists()


CONFIG_CASES = {
    "NaN": ("reward:\n  drawdown_penalty: .nan\n", "reward.drawdown_penalty: Input should be a finite number"),
    "+inf": ("market:\n  initial_liquidity: .inf\n", "market.initial_liquidity: Input should be a finite number"),
    "-inf": ("reward:\n  physics_penalty: -.inf\n", "reward.physics_penalty: Input should be a finite number"),
    "-1e308": (
        "reward:\n  unmet_demand_penalty: -1.0e+308\n",
        "reward.unmet_demand_penalty: Input should be greater than or equal to 0",
    ),
    "huge discrete_levels": ("discrete_levels: 1000000\n", "discrete_levels: Input should be less than or equal to 50"),
    "static ratio outside its range": (
        "market:\n  static_liquidity_ratio: 0.99\n",
        "market.static_liquidity_ratio = 0.99 is outside its range [0.2, 0.95]",
    ),
    "static burn above the maximum": (
        "market:\n  static_burn_rate: 0.5\n",
        "market.static_burn_rate = 0.5 is outside its range [0.0, 0.2]",
    ),
    "negative seed": ("seed: -3\n", "seed: Input should be greater than or equal to 0"),
    "duplicate key": (
        "seed: 1\nmarket:\n  max_burn_rate: 0.1\n  max_burn_rate: 0.3\n",
        "duplicate key 'max_burn_rate' (line 4, column 3)",
    ),
}


@pytest.mark.parametrize("case", sorted(CONFIG_CASES))
def test_config_values_are_finite_bounded_and_unique(tmp_path, case):
    text, message = CONFIG_CASES[case]
    path = tmp_path / "config.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_config_file_problems(tmp_path):
    path = tmp_path / "latin1.yaml"
    path.write_bytes("seed: 7  # r\xe9sum\xe9\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"latin1.yaml is not UTF-8 text \(byte 0xe9 at offset 12\)"):
        load_config(path)
    with pytest.raises(ConfigError, match=r"is a directory, not a file"):
        load_config(tmp_path)


def test_episode_longer_than_the_data_is_refused(tiny_dataset, tmp_path):
    config = BenchmarkConfig(episode_steps=97)
    with pytest.raises(ConfigError, match=r"episode_steps = 97 is longer than .*, which has 96 hours"):
        SolarChainEnv(tiny_dataset, config=config)
    SolarChainEnv(tiny_dataset, config=BenchmarkConfig(episode_steps=96))  # the whole window is fine
    path = tmp_path / "long.yaml"
    path.write_text("episode_steps: 500\n")
    _assert_refused(_evaluate(tiny_dataset, tmp_path / "run", "--config", str(path)), "episode_steps = 500")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("seeds", "message"),
    [("-1", "seed -1 is outside 0..4294967295"), ("1,1", "seed(s) 1 given twice"), ("3,4294967296", "seed 4294967296")],
)
def test_bad_run_seeds(tiny_dataset, tmp_path, seeds, message):
    result = CliRunner().invoke(
        app,
        ["evaluate", "--data", str(tiny_dataset), "--episodes", "1", "--seeds", seeds, "--out", str(tmp_path / "run")],
    )
    _assert_refused(result, message)
    assert not (tmp_path / "run").exists()


def _strict(text: str):
    def refuse(constant: str):
        raise AssertionError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


def test_run_json_is_strict(tiny_dataset, tmp_path):
    with pytest.raises(ValueError, match=r"non-finite number at metrics\[1\].std"):
        atomic_write_json(tmp_path / "x.json", {"metrics": [{"std": 0.0}, {"std": float("nan")}]})
    assert not (tmp_path / "x.json").exists()
    result = _evaluate(tiny_dataset, tmp_path / "run")
    assert result.exit_code == 0, result.output
    for name in ("summary.json", "run_metadata.json"):
        assert _strict((tmp_path / "run" / name).read_text())
