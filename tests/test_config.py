"""Configuration: the paper's YAML layout loads unchanged; mistakes are errors."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig, ConfigError, load_config

# The layout of the paper release's configs/month_2026_04.yaml.
PAPER_YAML = """\
seed: 20260511
episode_steps: 24
data_dir: data/datasets_2026_04_month
output_dir: outputs/runs
figures_dir: figures
action_mode: continuous
discrete_levels: 5
no_physics_penalty: false

market:
  initial_liquidity: 1.0
  initial_token_price: 1.0
  min_reward_ratio: 0.05
  max_reward_ratio: 0.65
  min_liquidity_ratio: 0.20
  max_liquidity_ratio: 0.95
  max_burn_rate: 0.20
  max_total_allocation: 0.98
  static_reward_ratio: 0.25
  static_liquidity_ratio: 0.75
  static_burn_rate: 0.02

reward:
  drawdown_penalty: 1.50
  action_jitter_penalty: 0.25
  unmet_demand_penalty: 0.40
  physics_penalty: 2.00
  fairness_penalty: 0.20

training:
  timesteps: 10000
  n_envs: 1
  learning_rate: 0.0003
  batch_size: 64
  gamma: 0.98

evaluation:
  episodes: 5
  policies:
    - static
    - random
    - myopic
"""


def test_the_papers_yaml_loads_unchanged(tmp_path):
    path = tmp_path / "month_2026_04.yaml"
    path.write_text(PAPER_YAML)
    with pytest.warns(UserWarning, match=r"'figures_dir' is not used"):
        config = load_config(path)
    assert config.data_dir == "data/datasets_2026_04_month"
    # Every value equals the documented default (docs/environment.md#arguments) except the data path
    # and the number of evaluation episodes (the release's file says 5; the paper's protocol is 30).
    assert config.evaluation.episodes == 5 and BenchmarkConfig().evaluation.episodes == 30
    exclude = {"data_dir": True, "evaluation": {"episodes"}}
    assert config.model_dump(exclude=exclude) == BenchmarkConfig().model_dump(exclude=exclude)
    assert config.training.learning_rate == 3e-4 and config.evaluation.policies == ["static", "random", "myopic"]


def test_unknown_keys_are_named(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text(PAPER_YAML.replace("  physics_penalty: 2.00", "  physics_penalty: 2.00\n  phyiscs_penalty: 3.0"))
    with pytest.raises(ConfigError, match=r"unknown key 'reward.phyiscs_penalty'"):
        load_config(path)


def test_missing_and_invalid_config_files(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "absent.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("market:\n  min_reward_ratio: 0.9\n")
    with pytest.raises(ConfigError, match="min_reward_ratio must be below"):
        load_config(bad)
    bad.write_text("action_mode: hybrid\n")
    with pytest.raises(ConfigError, match="action_mode"):
        load_config(bad)


def test_cli_reports_config_errors_with_exit_status_2(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text("seeed: 1\n")
    result = CliRunner().invoke(app, ["evaluate", "--config", str(path), "--episodes", "1", "--seeds", "1"])
    assert result.exit_code == 2
    assert "unknown key 'seeed'" in result.output
    result = CliRunner().invoke(app, ["evaluate", "--config", str(tmp_path / "nope.yaml")])
    assert result.exit_code == 2 and "config file not found" in result.output


def test_evaluate_reads_its_defaults_from_the_evaluation_section(tmp_path, tiny_dataset):
    """evaluation.episodes and evaluation.policies are honoured; the options win when given."""
    import pandas as pd

    path = tmp_path / "eval.yaml"
    path.write_text("evaluation:\n  episodes: 2\n  policies: [myopic]\n")
    args = ["evaluate", "--config", str(path), "--data", str(tiny_dataset), "--seeds", "5"]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "a")])
    assert result.exit_code == 0, result.output
    metrics = pd.read_csv(tmp_path / "a" / "metrics.csv")
    assert list(metrics["policy"]) == ["myopic", "myopic"] and list(metrics["episode"]) == [0, 1]
    result = CliRunner().invoke(app, [*args, "--episodes", "1", "--policies", "static", "--out", str(tmp_path / "b")])
    assert result.exit_code == 0, result.output
    metrics = pd.read_csv(tmp_path / "b" / "metrics.csv")
    assert list(metrics["policy"]) == ["static"] and list(metrics["episode"]) == [0]
