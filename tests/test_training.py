"""Training: hyperparameters, model round trip through plain SB3 ``.load``, resume after a kill,
replay-buffer checkpoints, TensorBoard episode scalars, and learned policies in ``evaluate``."""

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

from solarchain_eval.agents.registry import make_policy
from solarchain_eval.agents.sb3 import model_candidates, resolve_model_path
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.training.sb3_trainer import (
    TRAIN_LOG_FILE,
    TRAIN_METADATA_FILE,
    TrainingError,
    TrainSpec,
    dqn_learning_starts,
    train,
)

CLI = [sys.executable, "-c", "from solarchain_eval.cli import main; main()"]


def _observations(data_dir: Path, mode: str, n: int = 48) -> np.ndarray:
    env = SolarChainEnv(data_dir=data_dir, action_mode=mode)
    obs, _ = env.reset(seed=11)
    rows, rng = [], np.random.default_rng(0)
    while len(rows) < n:
        rows.append(obs)
        action = rng.integers(env.action_space.n) if mode == "discrete" else rng.random(3, dtype=np.float32)
        obs, _, _, truncated, _ = env.step(action)
        if truncated:
            obs, _ = env.reset()
    return np.asarray(rows)


def test_dqn_learning_starts_follows_the_original_rule():
    assert [dqn_learning_starts(n) for n in (1, 9, 10, 300, 999, 1000, 1001, 300_000)] == [
        1,
        1,
        1,
        30,
        99,
        100,
        100,
        100,
    ]


@pytest.fixture(scope="module")
def trained(tmp_path_factory, tiny_dataset) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("trained")
    steps = {"ppo": 100, "sac": 150, "dqn": 300}
    return {
        algo: train(TrainSpec(algo=algo, seed=5, timesteps=n, data_dir=tiny_dataset), root / algo).model_path
        for algo, n in steps.items()
    }


@pytest.mark.parametrize("algo", ["ppo", "sac", "dqn"])
def test_model_round_trip_through_plain_sb3_load(algo, trained, tiny_dataset):
    from stable_baselines3 import DQN, PPO, SAC

    cls = {"ppo": PPO, "sac": SAC, "dqn": DQN}[algo]
    model = cls.load(trained[algo], device="cpu")
    assert model.learning_rate == 3e-4 and model.batch_size == 64 and model.gamma == 0.98
    if algo == "dqn":
        assert model.action_space.n == 125 and model.learning_starts == 30
    if algo == "ppo":
        assert model.n_steps == 2048 and model.n_epochs == 10  # SB3 defaults are kept
    mode = "discrete" if algo == "dqn" else "continuous"
    observations = _observations(tiny_dataset, mode)
    # one observation at a time, as in an episode (a batched forward pass may differ in the last ulp)
    expected = np.asarray([model.predict(obs, deterministic=True)[0] for obs in observations])
    policy = make_policy(algo, BenchmarkConfig(), {algo: trained[algo]})
    assert policy.action_mode == mode
    got = np.asarray([policy.act(obs) for obs in observations]).reshape(expected.shape)
    np.testing.assert_array_equal(got, expected)
    # deterministic: a second pass gives the same actions
    np.testing.assert_array_equal(
        np.asarray([policy.act(obs) for obs in observations]).reshape(expected.shape), expected
    )


def test_training_outputs_and_episode_log(trained):
    out = trained["dqn"].parent
    meta = json.loads((out / TRAIN_METADATA_FILE).read_text())
    assert meta["complete"] and meta["timesteps_done"] == 300 and meta["resumed_from"] == []
    config = json.loads((out / "train_config.json").read_text())["identity"]
    assert config["hyperparameters"] == {"learning_rate": 3e-4, "batch_size": 64, "gamma": 0.98, "learning_starts": 30}
    assert config["action_mode"] == "discrete" and config["config"]["training"]["timesteps"] == 300
    log = pd.read_csv(out / TRAIN_LOG_FILE)
    assert len(log) == 300 // 24 and (log["episode_length"] == 24).all()
    assert list(log["end_timestep"]) == [24 * (i + 1) for i in range(len(log))]
    assert log["physics_violation_rate"].between(0, 1).all() and (log["artificial_liquidity_MWh"] >= 0).all()
    assert not (out / "checkpoints").exists()


def test_training_is_reproducible_given_the_seed(trained, tiny_dataset, tmp_path):
    from stable_baselines3 import DQN

    again = train(TrainSpec(algo="dqn", seed=5, timesteps=300, data_dir=tiny_dataset), tmp_path / "dqn").model_path
    a, b = DQN.load(trained["dqn"]), DQN.load(again)
    for (name, pa), (_, pb) in zip(a.policy.state_dict().items(), b.policy.state_dict().items(), strict=True):
        assert (pa == pb).all(), name
    logs = [pd.read_csv(p.parent / TRAIN_LOG_FILE)["episode_return"] for p in (trained["dqn"], again)]
    pd.testing.assert_series_equal(*logs)


def test_a_finished_training_is_not_redone_and_a_different_one_is_refused(trained, tiny_dataset):
    out = trained["dqn"].parent
    before = (out / "model.zip").stat().st_mtime_ns
    outcome = train(TrainSpec(algo="dqn", seed=5, timesteps=300, data_dir=tiny_dataset), out)
    assert outcome.already_complete and (out / "model.zip").stat().st_mtime_ns == before
    with pytest.raises(TrainingError, match=r"different training \(.*seed: 5 -> 6"):
        train(TrainSpec(algo="dqn", seed=6, timesteps=300, data_dir=tiny_dataset), out)


def test_replay_buffer_checkpoint_round_trip(tiny_dataset, tmp_path):
    from stable_baselines3 import SAC

    from solarchain_eval.training.callbacks import load_replay_buffer, save_replay_buffer

    env = SolarChainEnv(data_dir=tiny_dataset)
    model = SAC("MlpPolicy", env, seed=1, learning_starts=200, device="cpu")
    model.learn(120)
    save_replay_buffer(model.replay_buffer, tmp_path / "buffer.npz")
    assert (tmp_path / "buffer.npz").stat().st_size < 100_000  # the filled rows only
    fresh = SAC("MlpPolicy", env, seed=2, device="cpu")
    load_replay_buffer(fresh.replay_buffer, tmp_path / "buffer.npz")
    old, new = model.replay_buffer, fresh.replay_buffer
    assert (new.pos, new.full) == (old.pos, old.full) == (120, False)
    for name in ("observations", "next_observations", "actions", "rewards", "dones", "timeouts"):
        np.testing.assert_array_equal(getattr(new, name), getattr(old, name), err_msg=name)


def test_killed_training_resumes_from_its_last_checkpoint(tiny_dataset, tmp_path):
    out = tmp_path / "sac"
    cmd = [
        *CLI,
        "train",
        "--algo",
        "sac",
        "--seed",
        "3",
        "--timesteps",
        "600",
        "--checkpoint-every",
        "150",
        "--data",
        str(tiny_dataset),
        "--out",
        str(out),
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    state = out / "checkpoints" / "state.json"
    deadline = time.monotonic() + 120
    while not state.is_file() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert state.is_file(), "no checkpoint appeared before the kill"
    checkpoint = json.loads(state.read_text())
    assert (
        not (out / TRAIN_METADATA_FILE).exists() or not json.loads((out / TRAIN_METADATA_FILE).read_text())["complete"]
    )
    for name in checkpoint["files"].values():
        assert (out / "checkpoints" / name).is_file()
    rows_before = pd.read_csv(out / "checkpoints" / checkpoint["files"]["log"])

    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "resumed from the checkpoint(s) at step" in done.stdout
    meta = json.loads((out / TRAIN_METADATA_FILE).read_text())
    assert meta["complete"] and meta["resumed_from"] == [checkpoint["steps"]] and meta["timesteps_done"] == 600
    log = pd.read_csv(out / TRAIN_LOG_FILE)
    pd.testing.assert_frame_equal(log.iloc[: len(rows_before)], rows_before)  # the first session's episodes are kept
    assert list(log["episode"]) == list(range(len(log))) and log["end_timestep"].is_monotonic_increasing
    assert log["end_timestep"].iloc[len(rows_before)] > checkpoint["steps"]
    assert not (out / "checkpoints").exists()


def test_tensorboard_gets_per_episode_violation_and_artificial_liquidity(tiny_dataset, tmp_path):
    pytest.importorskip("tensorboard")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out = train(
        TrainSpec(algo="dqn", seed=1, timesteps=120, data_dir=tiny_dataset, tensorboard_dir=tmp_path / "tb"),
        tmp_path / "m",
    )
    runs = list((tmp_path / "tb").iterdir())
    assert [r.name for r in runs] == ["dqn-main-1_1"]
    events = EventAccumulator(str(runs[0]))
    events.Reload()
    log = pd.read_csv(out.out_dir / TRAIN_LOG_FILE)
    for tag, column in (
        ("episode/physics_violation_rate", "physics_violation_rate"),
        ("episode/artificial_liquidity_MWh", "artificial_liquidity_MWh"),
    ):
        scalars = events.Scalars(tag)
        assert [s.step for s in scalars] == list(log["end_timestep"])
        np.testing.assert_allclose([s.value for s in scalars], log[column], rtol=1e-6)


def test_model_lookup_in_a_models_directory(tmp_path, trained):
    (tmp_path / "ppo.zip").write_bytes(trained["ppo"].read_bytes())
    assert resolve_model_path("ppo", {"*": tmp_path}) == tmp_path / "ppo.zip"
    assert resolve_model_path("sac", {"*": trained["sac"].parent}) == trained["sac"]  # a training directory
    assert resolve_model_path("dqn", {"dqn": trained["dqn"].parent}) == trained["dqn"]
    # a training directory of another algorithm is not taken for this one
    assert trained["sac"].parent / "model.zip" not in model_candidates("ppo", {"*": trained["sac"].parent})
    with pytest.raises(
        FileNotFoundError, match=r"no trained model for policy 'dqn': looked for .*dqn\.zip, .*dqn/model\.zip"
    ):
        resolve_model_path("dqn", {"*": tmp_path})
    with pytest.raises(FileNotFoundError, match="needs a trained model: pass models DIR") as caught:
        resolve_model_path("sac", {})
    assert "pass --models DIR or --models sac=PATH" in caught.value.message_for()
    with pytest.raises(ValueError, match=r"cannot load .*ppo\.zip as a SAC model"):
        make_policy("sac", BenchmarkConfig(), {"sac": tmp_path / "ppo.zip"})


def test_evaluate_cli_runs_learned_policies(tmp_path, trained, tiny_dataset):
    models = tmp_path / "models"
    models.mkdir()
    for algo, path in trained.items():
        (models / f"{algo}.zip").write_bytes(path.read_bytes())
    out = tmp_path / "run"
    done = subprocess.run(
        [
            *CLI,
            "evaluate",
            "--policies",
            "ppo,sac,dqn",
            "--models",
            str(models),
            "--seeds",
            "4",
            "--episodes",
            "2",
            "--data",
            str(tiny_dataset),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    actions = pd.read_csv(out / "actions.csv")
    assert list(actions.groupby("policy", sort=False).size().items()) == [("ppo", 48), ("sac", 48), ("dqn", 48)]
    # DQN executes points of the 5-level grid: α = 0.05 + 0.60 u with u in {0, .25, .5, .75, 1} (before sanitizing)
    dqn = actions[actions["policy"] == "dqn"]
    assert set(np.round(dqn["burn_rate"], 6)) <= {0.0, 0.05, 0.1, 0.15, 0.2}
    missing = subprocess.run(
        [
            *CLI,
            "evaluate",
            "--policies",
            "sac",
            "--models",
            str(tmp_path / "nowhere"),
            "--data",
            str(tiny_dataset),
            "--out",
            str(tmp_path / "x"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert missing.returncode == 2 and "no trained model for policy 'sac'" in missing.stderr
