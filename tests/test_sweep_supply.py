"""``solarchain-eval sweep --task supply-chain``: datasets built by the supply builder, results from
the supply task's declarations; the solar sweep's dataset keys unchanged."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.experiments.sweep_spec import SweepDataset, SweepError, dataset_key, load_sweep
from solarchain_eval.supply.build import build_supply_dataset
from solarchain_eval.supply.dataset import SUPPLY_DATASET
from solarchain_eval.supply.files import MANIFEST_FILE, SUPPLY_FILES
from solarchain_eval.tasks import DatasetBuilder, ScenarioDatasetBuilder, dataset_of, get_task
from solarchain_eval.tasks.base import episode_cost_fields

TINY = """
grid:
  timesteps: 10
  episodes: 2
  seeds: [7]
  settings: [main, no_physics]
  policies: [static, myopic]
dataset:
  start: "2024-01-01"
  end: "2024-03-01"
  seed: 7
axes:
  fdia_rate: [0.0, 0.3]
  fdia_pattern: [uniform, stealthy]
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "sweep.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_a_supply_sweep_runs_end_to_end_with_the_supply_columns(tmp_path):
    root = tmp_path / "out"
    result = CliRunner().invoke(
        app, ["sweep", str(_write(tmp_path, TINY)), "--out", str(root), "--task", "supply-chain"]
    )
    assert result.exit_code == 0, result.output
    results = pd.read_csv(root / "results.csv")
    # 4 points x 2 settings x 2 policies x 1 seed x 2 episodes, each point's rows complete
    assert len(results) == 4 * 2 * 2 * 2
    assert results.groupby("point").size().to_dict() == {
        f"fdia_rate-{r}__fdia_pattern-{p}": 8 for r in ("0.0", "0.3") for p in ("uniform", "stealthy")
    }
    supply = [m.name for m in get_task("supply-chain").metrics]
    assert list(results.columns) == [
        "point", "cost_limit", "fdia_rate", "fdia_pattern",
        "policy", "setting", "run_seed", "episode", "episode_seed", "start_hour",
        *supply, "episode_cost",
    ]  # fmt: skip
    # episode_cost is the sum of the steps' V + A (A in days of demand): the feasibility term the
    # main setting's reward charges with λp = 2, and no_physics does not.
    key = ["point", "policy", "run_seed", "episode"]
    main = results[results["setting"] == "main"].set_index(key).sort_index()
    free = results[results["setting"] == "no_physics"].set_index(key).sort_index()
    assert (main["episode_cost"] > 0).sum() >= 8  # the check below is not 0 == 0
    gap = free["cumulative_reward"] - main["cumulative_reward"]
    np.testing.assert_allclose(gap, 2.0 * main["episode_cost"], rtol=1e-6)

    # The rate axis changes the dataset, and the phantom stock released on a fixed policy follows it.
    meta = json.loads((root / "sweep_metadata.json").read_text())
    assert meta["complete"] and meta["results_rows"] == 32
    dirs = {p: Path(v["data_dir"]) for p, v in meta["points"].items()}
    assert len(set(dirs.values())) == 4  # every rate x pattern is a dataset of its own
    manifests = {p: json.loads((d / MANIFEST_FILE).read_text()) for p, d in dirs.items()}
    calm, attacked = manifests["fdia_rate-0.0__fdia_pattern-uniform"], manifests["fdia_rate-0.3__fdia_pattern-uniform"]
    assert calm["files"] != attacked["files"]
    assert calm["fdia"]["injected_records"] == 0 and attacked["fdia"]["injected_records"] == round(0.3 * 60 * 5)
    assert calm["start"] == "2024-01-01" and calm["days"] == 60 and calm["seed"] == 7
    static = results[(results["policy"] == "static") & (results["setting"] == "main")]
    phantom = static.groupby("point")["phantom_fill_volume_units"].mean()
    assert phantom["fdia_rate-0.0__fdia_pattern-uniform"] == 0.0
    assert phantom["fdia_rate-0.3__fdia_pattern-uniform"] > phantom["fdia_rate-0.3__fdia_pattern-stealthy"] > 100.0
    # The sensitivity tables cover the supply metrics.
    table = pd.read_csv(root / "sensitivity" / "sensitivity.csv")
    assert {"phantom_backed_units", "phantom_fill_volume_units", "episode_cost"} <= set(table["metric"])


def test_a_supply_sweep_takes_the_supply_builders_defaults_and_refuses_solar_keys(tmp_path):
    sweep = load_sweep(_write(tmp_path, "axes: {fdia_rate: [0.1]}\n"), task="supply-chain")
    (point,) = sweep.points
    assert sweep.task == "supply-chain"
    assert (point.dataset.seed, point.dataset.start, point.dataset.end) == (20260511, "2024-01-01", "2024-12-30")
    assert point.dataset_key != dataset_key(point.dataset)  # the supply key names the task and its parameters
    with pytest.raises(SweepError, match=r"sweep\.yaml: dataset\.cities: the supply-chain task's datasets take no"):
        load_sweep(_write(tmp_path, "dataset: {cities: 3}\n"), task="supply-chain")
    with pytest.raises(SweepError, match=r"sweep\.yaml: axes\.nodes_per_city: the supply-chain task's datasets"):
        load_sweep(_write(tmp_path, "axes: {nodes_per_city: [2, 3]}\n"), task="supply-chain")
    # From the command line: one line, exit 2, nothing written.
    out = tmp_path / "never"
    result = CliRunner().invoke(
        app, ["sweep", str(tmp_path / "sweep.yaml"), "--out", str(out), "--task", "supply-chain"]
    )
    assert result.exit_code == 2 and "axes.nodes_per_city" in result.output and not out.exists()
    bad = _write(tmp_path, "dataset: {start: '2024-01-05', end: '2024-01-05'}\n")
    result = CliRunner().invoke(app, ["sweep", str(bad), "--out", str(out), "--task", "supply-chain"])
    assert result.exit_code == 2 and "must be 1 to" in result.output


def test_the_supply_builder_builds_byte_reproducibly(tmp_path):
    builder = dataset_of(get_task("supply-chain"))
    assert builder is SUPPLY_DATASET and isinstance(builder, ScenarioDatasetBuilder)
    assert not isinstance(builder, DatasetBuilder)  # no weather, cities or families to fake
    assert builder.false_data.patterns == ("uniform", "clustered", "stealthy")
    params = dict(seed=3, start="2024-02-05", end="2024-03-04", fdia_rate=0.2, fdia_pattern="clustered")
    params.update(fdia_severity="1.2:1.6", fdia_burst_hours=4)
    first = builder.build_point(tmp_path / "a", params)
    builder.build_point(tmp_path / "b", params)
    direct = build_supply_dataset(
        tmp_path / "c", seed=3, days=28, start="2024-02-05", fdia=builder.scenario(0.2, "1.2:1.6", "clustered", 4)
    )
    for name in (*SUPPLY_FILES, MANIFEST_FILE):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "c" / name).read_bytes()
    assert first == direct
    assert first["days"] == 28 and first["fdia"]["burst_days"] == 4 and first["fdia"]["injected_records"] == 28
    rows = dict(builder.check(tmp_path / "a"))
    assert rows["spoofed reports"] == "28" and rows["days"].startswith("28 from 2024-02-05")


def test_the_solar_sweep_keeps_its_dataset_keys_and_cost_fields(tmp_path):
    # Keys of sweep roots made before the builder capability (a changed hash would rebuild them).
    assert dataset_key(SweepDataset()) == "ds-faf5ca2221f2"
    assert dataset_key(SweepDataset(fdia_rate=0.15, fdia_pattern="stealthy")) == "ds-c78800fd450b"
    sweep = load_sweep(_write(tmp_path, "axes: {fdia_rate: [0.05, 0.15], fdia_pattern: [uniform, stealthy]}\n"))
    assert sweep.task == "solar" and [p.dataset_key for p in sweep.points][::3] == [
        "ds-faf5ca2221f2",
        "ds-c78800fd450b",
    ]
    assert episode_cost_fields(get_task("solar")) == ("physics_violation_rate", "unsafe_backed_MWh")
    assert episode_cost_fields(get_task("supply-chain")) == ("cost",)
