"""Training, the benches and the paper grid on a task other than the solar market (tests/toy_task.py).

The toy market reaches them only through the task registry: nothing in training/, perf/ or
experiments/ names it.
"""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.experiments.grid import GridSpec
from solarchain_eval.experiments.grid_root import grid_identity
from solarchain_eval.tasks import get_task, register_task, unregister_task
from solarchain_eval.tasks.base import TrainLogField, has_jax_env, make_jax_env, make_vector_env, training_log_fields
from solarchain_eval.training.sb3_trainer import TRAIN_LOG_FILE, TrainSpec, _identity, train
from toy_task import STEPS, TOY_TASK, ToyTask

runner = CliRunner()


class _CountingSteps(gym.Wrapper):
    """The toy env with ``info["one"] = 1.0`` at every step: its episode sum is the length, its mean 1."""

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {**info, "one": 1.0}


class LoggedToyTask(ToyTask):
    """The toy market with training-log columns (the optional ``training_log`` capability)."""

    name = "toy-logged"
    training_log = (
        TrainLogField("ones_summed", "one"),
        TrainLogField("ones_averaged", "one", mean=True),
        TrainLogField("shortfall_units", "shortfall"),
    )

    def make_env(self, config, data, *, action_mode=None):
        return _CountingSteps(super().make_env(config, data, action_mode=action_mode))


@pytest.fixture
def toy_tasks():
    register_task(TOY_TASK)
    register_task(LoggedToyTask())
    yield
    unregister_task(TOY_TASK.name)
    unregister_task(LoggedToyTask.name)


def test_the_optional_training_capabilities_have_defaults(toy_tasks):
    solar = get_task()
    assert has_jax_env(solar) and not has_jax_env(TOY_TASK)
    assert make_jax_env(TOY_TASK, None, None) is None
    assert training_log_fields(TOY_TASK) == ()
    assert [f.column for f in training_log_fields(solar)] == [
        "episode_volume",
        "physics_violation_rate",
        "artificial_liquidity_MWh",
        "episode_cost",
    ]
    # Without a vector env of its own, a task's sub-envs are its single envs, seeded s + i.
    envs = make_vector_env(TOY_TASK, None, None, 3)
    assert isinstance(envs, gym.vector.SyncVectorEnv) and envs.num_envs == 3
    obs, _ = envs.reset(seed=5)
    single = TOY_TASK.make_env(None, None)
    for i in range(3):
        assert np.array_equal(obs[i], single.reset(seed=5 + i)[0])
    actions = np.tile(np.float32([0.4, 0.3, 0.1]), (3, 1))
    _, rewards, _, _, _ = envs.step(actions)
    single.reset(seed=7)
    assert rewards[2] == single.step(actions[2])[1]


def test_the_solar_markets_vector_env_is_its_native_one(tiny_dataset):
    from solarchain_eval.envs.vector import SolarChainVectorEnv

    solar = get_task()
    envs = make_vector_env(solar, BenchmarkConfig(), solar.load_data(tiny_dataset), 4, autoreset_mode="SameStep")
    assert isinstance(envs, SolarChainVectorEnv) and envs.num_envs == 4
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP


def test_the_toy_task_trains_with_sb3_ppo_through_the_trainer(toy_tasks, tmp_path):
    outcome = train(TrainSpec(algo="ppo", seed=3, timesteps=256, task="toy-stock", checkpoint_every=0), tmp_path)
    assert outcome.model_path.is_file() and outcome.timesteps_done == 2048  # one whole PPO rollout
    log = pd.read_csv(tmp_path / TRAIN_LOG_FILE)
    assert list(log.columns) == ["episode", "end_timestep", "episode_return", "episode_length", "wall_s"]
    assert len(log) == 2048 // STEPS and set(log["episode_length"]) == {STEPS}
    recorded = json.loads((tmp_path / "train_config.json").read_text())
    assert recorded["identity"]["task"] == "toy-stock" and recorded["data_dir"] is None
    # the same spec on the solar market records no task: its identity (and resumes) are the ones before tasks
    assert "task" not in _identity(TrainSpec("ppo", 3, 256), {})
    assert _identity(TrainSpec("ppo", 3, 256, task="toy-stock"), {})["task"] == "toy-stock"


def test_a_tasks_training_log_columns_sum_or_average_its_info(toy_tasks, tmp_path):
    train(TrainSpec(algo="ppo", seed=1, timesteps=256, task="toy-logged", checkpoint_every=0), tmp_path)
    log = pd.read_csv(tmp_path / TRAIN_LOG_FILE)
    assert list(log.columns) == [
        "episode",
        "end_timestep",
        "episode_return",
        "episode_length",
        "ones_summed",
        "ones_averaged",
        "shortfall_units",
        "wall_s",
    ]
    assert (log["ones_summed"] == STEPS).all() and (log["ones_averaged"] == 1.0).all()
    assert (log["shortfall_units"] >= 0).all() and log["shortfall_units"].sum() > 0


def test_train_and_bench_take_a_task_and_jax_needs_its_env(toy_tasks, tmp_path):
    result = runner.invoke(
        app, ["train", "--task", "toy-stock", "--algo", "ppo", "--timesteps", "256", "--out", str(tmp_path / "t")]
    )
    assert result.exit_code == 0, result.output
    assert json.loads((tmp_path / "t" / "train_config.json").read_text())["identity"]["task"] == "toy-stock"
    for command in (
        ["train", "--task", "toy-stock", "--algo", "ppo", "--backend", "jax", "--out", str(tmp_path / "j")],
        ["bench", "--task", "toy-stock", "--backend", "jax"],
    ):
        result = runner.invoke(app, command)
        assert result.exit_code == 2, result.output
        assert "toy-stock" in result.output and "has no JAX environment" in result.output
        assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "j").exists()
    result = runner.invoke(app, ["train", "--task", "no-such-market", "--algo", "ppo", "--out", str(tmp_path / "u")])
    assert result.exit_code == 2 and "unknown task 'no-such-market'" in result.output


def test_bench_measures_the_named_tasks_envs(toy_tasks):
    result = runner.invoke(
        app,
        ["bench", "--task", "toy-stock", "--steps", "1000", "--num-envs", "4", "--calls", "25", "--repeats", "1"],
    )
    assert result.exit_code == 0, result.output
    assert "single env" in result.output and "vector env, 4 envs" in result.output
    assert "evaluation timing is the solar market's" in result.output
    # Beside the solar market's single env in the same run, and the ratio of the medians.
    rows = {
        line.split("│")[1].strip(): line.split("│")[2].strip() for line in result.output.splitlines()[1:] if "│" in line
    }
    toy = float(rows["single env (gym.make, random actions, resets included), task toy-stock"].replace(",", ""))
    solar = float(rows["single env (gym.make, random actions, resets included), task solar"].replace(",", ""))
    ratio = rows["ratio single env toy-stock / solar (medians)"]
    assert ratio.endswith("x") and abs(float(ratio[:-1]) - toy / solar) <= 0.006  # from the rounded medians


def test_a_grid_names_its_task_only_when_it_is_not_the_solar_market(toy_tasks):
    dataset = {"files": {}}
    solar = grid_identity(GridSpec.from_preset("smoke"), dataset)
    toy = grid_identity(GridSpec.from_preset("smoke", task="toy-stock"), dataset)
    assert "task" not in solar and toy == {**solar, "task": "toy-stock"}
    with pytest.raises(ValueError, match="task 'toy-stock' has none"):
        GridSpec.from_preset("smoke", task="toy-stock", backend="jax", settings=("main",)).validate()
    with pytest.raises(ValueError, match="settings llm, llm_no_physics run the Planner/Auditor layer, and task"):
        GridSpec.from_preset("smoke", task="toy-stock").validate()


def test_sweep_takes_a_task_and_builds_datasets_only_with_its_builder(toy_tasks, tmp_path):
    spec = tmp_path / "sweep.yaml"
    spec.write_text(
        """
grid: {timesteps: 10, episodes: 1, seeds: [7], settings: [main], policies: [static]}
dataset: {start: "2026-06-01", end: "2026-06-03", seed: 7}
axes:
  lambda_p: [0.0, 2.0]
""",
        encoding="utf-8",
    )
    result = runner.invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "out"), "--task", "toy-stock"])
    assert result.exit_code == 2, result.output
    assert "task 'toy-stock' has no dataset builder; its sweep takes its dataset as dataset.data" in result.output
    assert str(spec.name) in result.output
    assert not (tmp_path / "out" / "datasets").exists()
    result = runner.invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "u"), "--task", "no-such-market"])
    assert result.exit_code == 2 and "unknown task 'no-such-market'" in result.output
