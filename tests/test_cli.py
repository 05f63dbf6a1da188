"""The command line: main job, evaluate outputs, errors, atomic files."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import atomic_write_csv, atomic_write_text
from solarchain_eval.evaluation.rollout import STEP_FIELDS
from solarchain_eval.records_schema import METRIC_NAMES

runner = CliRunner()


def test_main_job_runs_on_the_embedded_default_dataset(tmp_path):
    result = runner.invoke(app, ["run", "--out", str(tmp_path / "run"), "--episodes", "4"])
    assert result.exit_code == 0, result.output
    for policy in ("static", "random", "myopic"):
        assert policy in result.output
    metrics = pd.read_csv(tmp_path / "run" / "metrics.csv")
    assert len(metrics) == 3 * 3 * 4
    assert set(metrics["setting"]) == {"main"}


def test_evaluate_writes_every_file_with_the_documented_columns(tiny_dataset, tmp_path):
    out = tmp_path / "run"
    result = runner.invoke(
        app,
        [
            "evaluate",
            "--data",
            str(tiny_dataset),
            "--policies",
            "static,myopic",
            "--seeds",
            "1,2",
            "--episodes",
            "3",
            "--out",
            str(out),
            "--no-physics-penalty",
        ],
    )
    assert result.exit_code == 0, result.output
    metrics = pd.read_csv(out / "metrics.csv")
    assert list(metrics.columns) == [
        "policy",
        "setting",
        "run_seed",
        "episode",
        "episode_seed",
        "start_hour",
        *METRIC_NAMES,
    ]
    assert len(metrics) == 12 and set(metrics["setting"]) == {"no_physics"}
    assert metrics["episode_seed"].tolist()[:3] == [1, 2, 3]
    actions = pd.read_csv(out / "actions.csv")
    assert len(actions) == 12 * 24
    assert list(actions.columns) == ["policy", "setting", "run_seed", "episode", "episode_seed", "step", *STEP_FIELDS]
    city_hour = pd.read_csv(out / "city_hour_policy.csv")
    assert len(city_hour) == 12 * 24 * 3
    # The episode's city rewards add up to what its fairness index was computed from.
    first = city_hour[(city_hour["policy"] == "static") & (city_hour["run_seed"] == 1) & (city_hour["episode"] == 0)]
    totals = first.groupby("city")["city_reward"].sum().to_numpy()
    assert metrics.loc[0, "spatial_fairness_index"] == pytest.approx(totals.var() / abs(totals).mean(), rel=1e-9)
    summary = json.loads((out / "summary.json").read_text())
    assert {(s["policy"], s["setting"], s["episodes"]) for s in summary} == {
        ("static", "no_physics", 6),
        ("myopic", "no_physics", 6),
    }
    meta = json.loads((out / "run_metadata.json").read_text())
    assert meta["complete"] and meta["setting"] == "no_physics" and meta["rows"] == {"metrics": 12, "actions": 288}
    assert meta["config"]["no_physics_penalty"] is True
    assert set(meta["dataset"]["files"]) == {
        "urban_energy_nodes.csv",
        "spatiotemporal_generation.csv",
        "market_liquidity.csv",
        "p2p_trades.csv",
    }
    assert "numpy" in meta["package_versions"]


def test_unknown_policy_exits_2_before_writing(tiny_dataset, tmp_path):
    result = runner.invoke(
        app, ["evaluate", "--data", str(tiny_dataset), "--policies", "static,oracle", "--out", str(tmp_path / "r")]
    )
    assert result.exit_code == 2
    assert "unknown policy 'oracle'" in result.output
    assert not (tmp_path / "r").exists()


def test_data_build_refuses_to_overwrite_without_force(tmp_path):
    args = [
        "data",
        "build",
        "--out",
        str(tmp_path / "ds"),
        "--city",
        "Wuhan:30.5928:114.3055",
        "--start",
        "2026-05-01",
        "--end",
        "2026-05-03",
        "--nodes-per-city",
        "2",
    ]
    assert runner.invoke(app, args).exit_code == 0
    again = runner.invoke(app, args)
    assert again.exit_code == 2 and "--force" in again.output
    assert runner.invoke(app, [*args, "--force"]).exit_code == 0
    assert len(pd.read_csv(tmp_path / "ds" / "spatiotemporal_generation.csv")) == 2 * 48


def test_help_explains_every_command():
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for command in ("run", "evaluate", "bench", "data"):
        assert command in result.output


def test_interrupted_writes_leave_no_file(tmp_path):
    class Boom(Exception):
        pass

    class FailingFrame:
        def to_csv(self, path, **kwargs):
            Path(path).write_text("policy,setting\nhalf")
            raise Boom

    target = tmp_path / "metrics.csv"
    with pytest.raises(Boom):
        atomic_write_csv(target, FailingFrame())
    assert list(tmp_path.iterdir()) == []
    atomic_write_text(target, "old")
    with pytest.raises(Boom):
        atomic_write_csv(target, FailingFrame())
    assert target.read_text() == "old"  # the previous complete file survives
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.csv"]
