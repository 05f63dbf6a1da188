"""``solarchain-eval compare``: differences of two runs' means with start-day intervals."""

from __future__ import annotations

import numpy as np
import pandas as pd
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.report.compare import compare_runs


def _run_dir(path, rewards, setting="main", policy="ppo", start_hours=(0, 24, 48, 72)):
    rows = []
    for episode, (reward, start) in enumerate(zip(rewards, start_hours, strict=True)):
        rows.append({
            "policy": policy, "setting": setting, "run_seed": 1, "episode": episode, "episode_seed": 1 + episode,
            "start_hour": start, "cumulative_reward": reward, "mean_slippage": 0.01 * reward,
        })  # fmt: skip
    path.mkdir()
    pd.DataFrame(rows).to_csv(path / "metrics.csv", index=False)
    return pd.DataFrame(rows)


def test_compare_prints_and_writes_the_differences(tmp_path):
    base = _run_dir(tmp_path / "base", [-23.0, -22.0, -24.0, -21.0])
    other = _run_dir(tmp_path / "other", [-22.0, -21.5, -23.0, -20.0])
    out = tmp_path / "cmp.csv"
    result = CliRunner().invoke(
        app, ["compare", str(tmp_path / "base"), str(tmp_path / "other"), "--metrics", "cumulative_reward",
              "--csv", str(out)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    written = pd.read_csv(out)
    assert list(written["metric"]) == ["cumulative_reward"]
    row = written.iloc[0]
    assert row["difference"] == np.mean([1.0, 0.5, 1.0, 1.0])  # every episode improved
    assert row["low"] > 0 and row["low"] <= row["difference"] <= row["high"]
    expected = compare_runs(base, other, ["cumulative_reward"])
    assert np.allclose(written[["low", "high"]].to_numpy(), expected[["low", "high"]].to_numpy())
    assert "0.88" in result.output and "*" in result.output


def test_compare_refuses_other_episodes_unknown_metrics_and_empty_dirs(tmp_path):
    _run_dir(tmp_path / "base", [-23.0, -22.0, -24.0, -21.0])
    _run_dir(tmp_path / "shifted", [-23.0, -22.0, -24.0, -21.0], start_hours=(0, 24, 48, 96))
    (tmp_path / "empty").mkdir()
    runner = CliRunner()
    cases = [
        (
            ["compare", str(tmp_path / "base"), str(tmp_path / "shifted"), "--metrics", "cumulative_reward"],
            "ppo in main: the two runs evaluated different episodes",
        ),
        (["compare", str(tmp_path / "base"), str(tmp_path / "base"), "--metrics", "nope"], "--metrics: nope"),
        (["compare", str(tmp_path / "base"), str(tmp_path / "empty")], f"OTHER: {tmp_path / 'empty'} holds no"),
    ]
    for args, message in cases:
        result = runner.invoke(app, args)
        assert result.exit_code == 2, result.output
        assert message in " ".join(result.output.split()), result.output
