"""``solarchain-eval sweep``: a tiny YAML end to end, resume after a kill, validation, sensitivity tables."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.experiments.sweep_spec import SweepError, load_sweep
from solarchain_eval.report.sensitivity import findings_table, sensitivity_table

TINY = """
grid:
  timesteps: 10
  episodes: 3
  seeds: [7, 8]
  settings: [main, no_physics]
  policies: [static, myopic]
dataset:
  cities: ["Wuhan:30.5928:114.3055", "Xian:34.3416:108.9398"]
  nodes_per_city: 2
  start: "2026-06-01"
  end: "2026-06-05"
  seed: 7
axes:
  fdia_pattern: [uniform, stealthy]
  lambda_p: [0.0, 2.0]
"""


def _write(tmp_path: Path, text: str = TINY) -> Path:
    path = tmp_path / "sweep.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def _starts(root: Path) -> dict[str, int]:
    """How many times each unit was started (its unit.log is append-only)."""
    return {
        str(log.parent.relative_to(root)): log.read_text().count(" start ")
        for log in sorted(root.glob("points/*/units/*/*/unit.log"))
    }


def test_tiny_sweep_end_to_end_and_resume(tmp_path):
    spec = _write(tmp_path)
    root = tmp_path / "out"
    runner = CliRunner()
    result = runner.invoke(app, ["sweep", str(spec), "--out", str(root)])
    assert result.exit_code == 0, result.output
    results = pd.read_csv(root / "results.csv")
    # 4 points x 2 settings x 2 policies x 2 seeds x 3 episodes
    assert len(results) == 4 * 2 * 2 * 2 * 3
    assert set(results["point"]) == {
        f"fdia_pattern-{p}__lambda_p-{w}" for p in ("uniform", "stealthy") for w in ("0.0", "2.0")
    }
    assert {"fdia_pattern", "lambda_p", "episode_cost", "cumulative_reward"} <= set(results.columns)
    # The λp axis acts on the reward of the main setting only where it differs: with λp = 0
    # the main and no_physics rewards coincide; with λp = 2 main is lower by 2 x cost.
    key = ["point", "policy", "run_seed", "episode"]
    main = results[results["setting"] == "main"].set_index(key).sort_index()
    free = results[results["setting"] == "no_physics"].set_index(key).sort_index()
    zero = main.index.get_level_values("point").str.endswith("lambda_p-0.0")
    np.testing.assert_allclose(main["cumulative_reward"][zero], free["cumulative_reward"][zero], rtol=1e-12)
    gap = (free["cumulative_reward"] - main["cumulative_reward"])[~zero]
    np.testing.assert_allclose(gap, 2.0 * main["episode_cost"][~zero], rtol=1e-6)
    # Stealthy points: the dataset has no injected record above P_max.
    meta = json.loads((root / "sweep_metadata.json").read_text())
    assert meta["complete"] and len(meta["points"]) == 4
    stealthy = Path(meta["points"]["fdia_pattern-stealthy__lambda_p-0.0"]["data_dir"])
    generation = pd.read_csv(stealthy / "spatiotemporal_generation.csv")
    hit = generation[generation["fdia_detected"]]
    assert len(hit) > 0 and (hit["P_reported_W"] <= hit["P_max_W"]).all()
    sensitivity = pd.read_csv(root / "sensitivity" / "sensitivity.csv")
    assert set(sensitivity["axis"]) == {"fdia_pattern", "lambda_p"}
    assert (sensitivity["ci_low"] <= sensitivity["mean"]).all() and (
        sensitivity["mean"] <= sensitivity["ci_high"]
    ).all()

    # Resume: two units lose their DONE marker (as if killed); only they run again.
    before = _starts(root)
    assert set(before.values()) == {1} and len(before) == 32
    redo = "points/fdia_pattern-stealthy__lambda_p-2.0/units/eval/myopic-main-8"
    (root / redo / "DONE").unlink()
    first_results = (root / "results.csv").read_bytes()
    result = runner.invoke(app, ["sweep", str(spec), "--out", str(root)])
    assert result.exit_code == 0, result.output
    assert "31 already done" in result.output
    after = _starts(root)
    assert {k: v for k, v in after.items() if v != 1} == {redo: 2}
    assert (root / "results.csv").read_bytes() == first_results


def test_a_killed_sweep_resumes_without_rerunning_finished_units(tmp_path):
    spec = _write(tmp_path, TINY.replace("episodes: 3", "episodes: 6"))
    root = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1] / "src")}
    cmd = [sys.executable, "-c", "from solarchain_eval.cli import main; main()", "sweep", str(spec), "--out", str(root)]
    process = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not list(root.glob("points/*/units/eval/*/DONE")) and time.monotonic() < deadline:
        time.sleep(0.01)
    process.send_signal(signal.SIGKILL)
    process.wait()
    finished = {str(p.parent.relative_to(root)) for p in root.glob("points/*/units/eval/*/DONE")}
    assert finished
    result = CliRunner().invoke(app, ["sweep", str(spec), "--out", str(root)])
    assert result.exit_code == 0, result.output
    starts = _starts(root)
    assert len(starts) == 32 and all(starts[name] == 1 for name in finished)
    assert len(pd.read_csv(root / "results.csv")) == 4 * 2 * 2 * 2 * 6


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("grid: {episodes: 0}", "grid.episodes"),
        ("grid: {epsiodes: 3}", "grid.epsiodes: unknown key"),
        ("axes: {fdia_rat: [0.1]}", "axes.fdia_rat: unknown axis"),
        ("axes: {fdia_rate: []}", "axes.fdia_rate: give at least one value"),
        ("axes: {fdia_rate: [0.1, 1.5]}", "axes.fdia_rate[1]"),
        ("axes: {fdia_pattern: [uniform, bursty]}", "axes.fdia_pattern[1]"),
        ("axes: {lambda_p: [-1]}", "axes.lambda_p[0]"),
        ("axes: {lambda_p: [1], physics_penalty: [2]}", "given twice"),
        ("dataset: {data: /x}\naxes: {fdia_rate: [0.1]}", "axes.fdia_rate[0]: a dataset axis needs build parameters"),
        ("axes: [1, 2]", "axes: Input should be a valid dictionary"),
        ("grid: {seeds: [1]\n", "is not valid YAML"),
    ],
)
def test_bad_yaml_is_a_one_line_error_naming_the_key(tmp_path, text, message):
    spec = _write(tmp_path, text)
    with pytest.raises(SweepError, match=message.replace("[", r"\[").replace("]", r"\]")) as info:
        load_sweep(spec)
    assert "\n" not in str(info.value) and str(spec) in str(info.value)
    result = CliRunner().invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and not (tmp_path / "out").exists()


def _frame(rl_gain: float, al_rise: float) -> pd.DataFrame:
    """A hand-made results table: 10 start days, one episode each, for static and ppo."""
    rng = np.random.default_rng(0)
    rows = []
    for setting, al in (("main", 1.0), ("no_physics", 1.0 + al_rise)):
        for policy, reward in (("static", 1.0), ("ppo", 1.0 + rl_gain)):
            for day in range(10):
                rows.append(
                    {"point": "p", "axis": "a", "policy": policy, "setting": setting, "start_hour": 24 * day,
                     "cumulative_reward": reward + 0.01 * rng.standard_normal(),
                     "artificial_liquidity_MWh": al + 0.01 * rng.standard_normal()}
                )  # fmt: skip
    return pd.DataFrame(rows)


@pytest.mark.parametrize(
    ("gain", "rise", "expected"), [(0.5, 0.5, "holds"), (-0.5, -0.5, "flips"), (0.0, 0.0, "unclear")]
)
def test_findings_verdicts_follow_the_interval(gain, rise, expected):
    findings = findings_table(_frame(gain, rise), ["axis"], resamples=500).set_index("finding")
    assert findings.loc["rl_over_heuristics", "verdict"] == expected
    assert findings.loc["rl_over_heuristics", "detail"] == ("ppo - static")
    assert findings.loc["artificial_liquidity_rise", "verdict"] == expected
    assert findings.loc["rl_over_heuristics", "estimate"] == pytest.approx(gain, abs=0.02)


def test_sensitivity_means_match_the_pooled_episodes():
    frame = _frame(0.5, 0.2)
    table = sensitivity_table(frame, ["axis"], resamples=500)
    row = table[(table["policy"] == "ppo") & (table["setting"] == "main") & (table["metric"] == "cumulative_reward")]
    expected = frame[(frame["policy"] == "ppo") & (frame["setting"] == "main")]["cumulative_reward"].mean()
    assert row["mean"].item() == pytest.approx(expected, rel=1e-12)
    assert row["start_days"].item() == 10 and row["ci_low"].item() < expected < row["ci_high"].item()


def test_a_sweep_trains_and_evaluates_learned_policies_inside_each_point(tmp_path):
    text = TINY.replace("seeds: [7, 8]", "seeds: [7]").replace(
        "policies: [static, myopic]", "policies: {main: [static, ppo], no_physics: [static, ppo, ppo-lag]}"
    )
    text = text.replace("  lambda_p: [0.0, 2.0]\n", "").replace("[uniform, stealthy]", "[uniform]")
    text += "ppo_lag: {cost_limit: 0.5, multiplier_lr: 0.2}\n"
    spec = _write(tmp_path, text)
    root = tmp_path / "out"
    result = CliRunner().invoke(app, ["sweep", str(spec), "--out", str(root)])
    assert result.exit_code == 0, result.output
    point = root / "points" / "fdia_pattern-uniform"
    trains = sorted(p.name for p in (point / "units" / "train").iterdir())
    assert trains == ["ppo-lag-no_physics-7", "ppo-main-7", "ppo-no_physics-7"]
    # Each eval unit used the model of its own point's train unit.
    from solarchain_eval.common.atomic_files import sha256_file

    for unit, model in (("ppo-main-7", "ppo-main-7"), ("ppo-lag-no_physics-7", "ppo-lag-no_physics-7")):
        recorded = json.loads((point / "units" / "eval" / unit / "unit.json").read_text())["model_sha256"]
        assert list(recorded.values()) == [sha256_file(point / "units" / "train" / model / "model.zip")]
    lag = pd.read_csv(point / "units" / "train" / "ppo-lag-no_physics-7" / "lagrangian_log.csv")
    assert lag["cost_limit"].eq(0.5).all() and lag["next_multiplier"].iloc[-1] > 0
    findings = pd.read_csv(root / "sensitivity" / "findings.csv")
    assert set(findings["finding"]) == {"rl_over_heuristics", "artificial_liquidity_rise", "cost_within_limit"}
    results = pd.read_csv(root / "results.csv")
    assert set(results.groupby("setting")["policy"].unique().map(frozenset)) == {
        frozenset({"static", "ppo"}),
        frozenset({"static", "ppo", "ppo-lag"}),
    }


def test_a_sweep_through_ray_ships_each_points_dataset(tmp_path):
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install -e '.[ray]')")
    from solarchain_eval.experiments.sweep import run_sweep

    sweep = load_sweep(_write(tmp_path, TINY.replace("seeds: [7, 8]", "seeds: [7]")))
    inline = run_sweep(sweep, tmp_path / "inline")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        # ship the files through Ray as on a cluster without a shared filesystem: each task must
        # get its own point's dataset (uniform and stealthy are different datasets)
        shipped = run_sweep(sweep, tmp_path / "ray", ray_address="auto", ray_transfer="always")
    finally:
        ray.shutdown()
    assert inline.all_points and shipped.all_points and len(shipped.report.finished) == 16
    a = pd.read_csv(tmp_path / "inline" / "results.csv")
    b = pd.read_csv(tmp_path / "ray" / "results.csv")
    pd.testing.assert_frame_equal(a, b)
    stealthy = a[a["fdia_pattern"] == "stealthy"]["episode_cost"].mean()
    assert stealthy < 0.8 * a[a["fdia_pattern"] == "uniform"]["episode_cost"].mean()


def test_node_and_city_axes_build_synthetic_datasets(tmp_path):
    text = """
grid: {timesteps: 10, episodes: 1, seeds: [7], settings: [main], policies: [static]}
dataset: {start: "2026-06-01", end: "2026-06-03", seed: 7}
axes:
  cities: [2, 3]
  nodes_per_city: [1, 4]
"""
    sweep = load_sweep(_write(tmp_path, text))
    assert [p.point_id for p in sweep.points] == [
        "cities-2__nodes_per_city-1",
        "cities-2__nodes_per_city-4",
        "cities-3__nodes_per_city-1",
        "cities-3__nodes_per_city-4",
    ]
    result = CliRunner().invoke(app, ["sweep", str(tmp_path / "sweep.yaml"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    meta = json.loads((tmp_path / "out" / "sweep_metadata.json").read_text())
    for point in sweep.points:
        data_dir = Path(meta["points"][point.point_id]["data_dir"])
        nodes = pd.read_csv(data_dir / "urban_energy_nodes.csv")
        cities, per_city = point.values["cities"], point.values["nodes_per_city"]
        assert len(nodes) == cities * per_city and nodes["city"].nunique() == cities
        assert json.loads((data_dir / "manifest.json").read_text())["weather_source"].startswith("synthetic")
    assert len(pd.read_csv(tmp_path / "out" / "results.csv")) == 4


def test_a_busy_sweep_root_is_a_one_line_error_naming_the_sweep(tmp_path):
    """A second run on a locked root exits 2 before any work, and names the command that runs there."""
    import fcntl

    root = tmp_path / "out"
    root.mkdir()
    with open(root / ".lock", "a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        result = CliRunner().invoke(app, ["sweep", str(_write(tmp_path)), "--out", str(root)])
    assert result.exit_code == 2, result.output
    assert "another 'sweep' run is using" in result.output
    assert sorted(p.name for p in root.iterdir()) == [".lock"]  # nothing written
