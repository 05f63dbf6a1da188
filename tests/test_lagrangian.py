"""PPO-Lagrangian: the dual update, the penalised reward, a tiny training run, resume, CLI errors."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.training.lagrangian import (
    LAGRANGIAN_LOG_COLUMNS,
    LAGRANGIAN_LOG_FILE,
    LagrangianSettings,
    dual_update,
    log_frame,
    resume_multiplier,
)


def test_dual_update_follows_a_hand_computed_sequence():
    # λ0 = 0.2, lr = 0.5, D = 2: costs 3, 1, 0.5, (no episode), 5, 2
    lam, seen = 0.2, []
    for cost in (3.0, 1.0, 0.5, float("nan"), 5.0, 2.0):
        lam = dual_update(lam, cost, 2.0, 0.5)
        seen.append(lam)
    # 0.2 + 0.5 = 0.7; 0.7 - 0.5 = 0.2; max(0, 0.2 - 0.75) = 0; unchanged; 0 + 1.5; + 0
    assert seen == pytest.approx([0.7, 0.2, 0.0, 0.0, 1.5, 1.5], abs=1e-15)


def test_settings_refuse_negative_or_nan_values():
    with pytest.raises(ValueError, match="cost_limit"):
        LagrangianSettings(cost_limit=-1.0)
    with pytest.raises(ValueError, match="multiplier_lr"):
        LagrangianSettings(cost_limit=1.0, multiplier_lr=math.nan)


def test_penalised_reward_subtracts_lambda_times_cost(tiny_dataset):
    from stable_baselines3.common.vec_env import DummyVecEnv

    from solarchain_eval.envs.env import SolarChainEnv
    from solarchain_eval.training.lagrangian_callbacks import Multiplier, PenalisedReward

    def make():
        return SolarChainEnv(data_dir=tiny_dataset)

    plain, wrapped = DummyVecEnv([make]), PenalisedReward(DummyVecEnv([make]), Multiplier(2.5))
    plain.seed(3)
    wrapped.seed(3)
    plain.reset()
    wrapped.reset()
    action = np.array([[0.6, 0.8, 0.1]], dtype=np.float32)
    costs = []
    for _ in range(24):
        _, r, _, info = plain.step(action)
        _, rp, _, info_p = wrapped.step(action)
        costs.append(info[0]["cost"])
        assert info_p[0]["reward_unpenalised"] == pytest.approx(float(r[0]), abs=0)
        assert float(rp[0]) == pytest.approx(float(r[0]) - 2.5 * info[0]["cost"], rel=1e-6, abs=1e-6)
    assert max(costs) > 0.01


def test_resume_multiplier_keeps_the_rollouts_before_the_checkpoint(tmp_path):
    rows = [
        {"rollout": k, "end_timestep": 2048 * (k + 1), "episodes": 85, "episode_cost": 3.0, "cost_limit": 1.0,
         "violation": 2.0, "multiplier": 0.1 * k, "next_multiplier": 0.1 * (k + 1)}
        for k in range(3)
    ]  # fmt: skip
    path = tmp_path / LAGRANGIAN_LOG_FILE
    log_frame(rows).to_csv(path, index=False)
    settings = LagrangianSettings(cost_limit=1.0, initial_multiplier=0.05)
    lam, kept = resume_multiplier(path, settings, 4096)
    assert lam == pytest.approx(0.2) and [r["rollout"] for r in kept] == [0, 1]
    assert resume_multiplier(path, settings, 0) == (0.05, [])  # a fresh start ignores a stale log


def test_tiny_training_raises_the_multiplier_while_cost_exceeds_the_limit(tmp_path, tiny_dataset):
    from stable_baselines3 import PPO

    from solarchain_eval.agents.registry import make_policy
    from solarchain_eval.training.sb3_trainer import TrainSpec, train

    settings = LagrangianSettings(cost_limit=0.5, multiplier_lr=0.25, initial_multiplier=0.1)
    spec = TrainSpec(
        algo="ppo-lag", seed=1, timesteps=4096, data_dir=tiny_dataset, checkpoint_every=0, lagrangian=settings,
        tensorboard_dir=tmp_path / "tb",
    )  # fmt: skip
    outcome = train(spec, tmp_path / "run")
    log = pd.read_csv(tmp_path / "run" / LAGRANGIAN_LOG_FILE)
    assert list(log.columns) == list(LAGRANGIAN_LOG_COLUMNS) and len(log) == 2
    assert (log["episode_cost"] > settings.cost_limit).all()
    assert log["multiplier"].iloc[0] == 0.1
    assert log["multiplier"].iloc[1] == log["next_multiplier"].iloc[0]
    expected = np.maximum(0, log["multiplier"] + 0.25 * (log["episode_cost"] - 0.5))
    np.testing.assert_allclose(log["next_multiplier"], expected, rtol=1e-12)
    assert log["next_multiplier"].is_monotonic_increasing and log["next_multiplier"].iloc[-1] > 0.1
    np.testing.assert_allclose(log["violation"], log["episode_cost"] - 0.5)
    # TensorBoard got the multiplier.
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(next((tmp_path / "tb").iterdir())))
    events.Reload()
    scalars = [e.value for e in events.Scalars("lagrangian/multiplier")]
    assert scalars == pytest.approx(list(log["multiplier"]), rel=1e-6)
    # The episode log keeps the env's own reward r, not r - λ c: its last 100 returns average to
    # SB3's ep_rew_mean, which the Monitor (inside the penalty wrapper) computes from r.
    episodes = pd.read_csv(tmp_path / "run" / "training_log.csv")
    assert len(episodes) == 4096 // 24 and episodes["episode_cost"].gt(0).all()
    ep_rew_mean = events.Scalars("rollout/ep_rew_mean")[-1].value
    assert episodes["episode_return"].iloc[-100:].mean() == pytest.approx(ep_rew_mean, abs=1e-3)
    # model.zip is a plain PPO model and acts through the policy registry.
    PPO.load(outcome.model_path, device="cpu")
    policy = make_policy("ppo-lag", BenchmarkConfig(), {"ppo-lag": tmp_path / "run"})
    assert np.asarray(policy.act(np.zeros(12, dtype=np.float32))).shape == (3,)


def test_cli_refuses_ppo_lag_without_a_cost_limit_and_a_cost_limit_for_ppo(tmp_path, tiny_dataset):
    runner = CliRunner()
    base = ["train", "--timesteps", "10", "--data", str(tiny_dataset), "--out", str(tmp_path / "x")]
    result = runner.invoke(app, [*base, "--algo", "ppo-lag"])
    assert result.exit_code == 2 and "--cost-limit" in result.output
    result = runner.invoke(app, [*base, "--algo", "ppo", "--cost-limit", "3"])
    assert result.exit_code == 2 and "ppo-lag only" in result.output
    assert not (tmp_path / "x").exists()


def test_ppo_lag_is_opt_in_in_the_grid():
    from solarchain_eval.experiments.grid import GridSpec, plan_units

    default = [u.name for u in plan_units(GridSpec(timesteps=10, episodes=1, seeds=(1,), settings=("main",)))]
    assert not any("ppo-lag" in name for name in default) and "train/ppo-main-1" in default
    spec = GridSpec(
        timesteps=10, episodes=1, seeds=(1,), settings=("main", "no_physics"), policies=("static", "ppo-lag")
    )
    names = [u.name for u in plan_units(spec)]
    assert names == [
        "train/ppo-lag-main-1",
        "train/ppo-lag-no_physics-1",
        "eval/static-main-1",
        "eval/ppo-lag-main-1",
        "eval/static-no_physics-1",
        "eval/ppo-lag-no_physics-1",
    ]
    assert spec.uses_lagrangian and not GridSpec(timesteps=10, episodes=1, seeds=(1,)).uses_lagrangian


def test_paper_extra_policies_accepts_only_opt_in_policies(tmp_path, tiny_dataset):
    from solarchain_eval.cli.paper import _policies

    assert _policies(None, None, ("main",)) is None
    assert _policies(None, "ppo-lag", ("main",)) == ("static", "random", "myopic", "ppo", "sac", "dqn", "ppo-lag")
    assert _policies("static,ppo", "ppo-lag", ("main",)) == ("static", "ppo", "ppo-lag")
    result = CliRunner().invoke(
        app, ["paper", "--out", str(tmp_path / "root"), "--data", str(tiny_dataset), "--extra-policies", "sac"]
    )
    assert result.exit_code == 2 and "not an opt-in policy" in result.output
    assert not (tmp_path / "root").exists()
