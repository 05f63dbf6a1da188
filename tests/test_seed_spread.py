"""Training-seed spread and the seed bootstrap, on synthetic metrics whose answers are known."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from solarchain_eval.report.against_paper.paper_estimates import RunEstimates
from solarchain_eval.report.against_paper.paper_reference import Ref, paper_findings
from solarchain_eval.report.against_paper.seed_spread import (
    draw_seeds,
    finding_seed_share,
    ranking_seed_share,
    seed_decision,
    seed_ranking_table,
    seed_spread,
    seed_spread_table,
)
from solarchain_eval.report.loading import ReportData
from solarchain_eval.report.options import ReportOptions

EPISODES = 8
WITHIN = np.array([-1.5, -1.0, -0.5, 0.0, 0.0, 0.5, 1.0, 1.5])  # mean 0 within every seed


def rollouts(policy: str, seed_means: dict[int, float], column: str = "cumulative_reward") -> pd.DataFrame:
    """EPISODES rollouts per seed in the main setting: seed mean + WITHIN."""
    rows = [
        {
            "policy": policy,
            "setting": "main",
            "run_seed": seed,
            "episode": e,
            "episode_seed": seed + e,
            "start_hour": 24 * ((seed + e) % 7),
            column: mean + WITHIN[e],
        }
        for seed, mean in seed_means.items()
        for e in range(EPISODES)
    ]
    return pd.DataFrame(rows)


def reward_run(sac: dict[int, float], ppo: float = 1.0) -> pd.DataFrame:
    """The paper's order below PPO (Myopic > DQN > Static > Random), PPO constant over seeds, SAC as given."""
    seeds = (1, 2, 3)
    frames = [rollouts(p, {s: v for s in seeds}) for p, v in (("static", -60.0), ("random", -80.0), ("myopic", -40.0))]
    frames += [rollouts("ppo", {s: ppo for s in seeds}), rollouts("dqn", {s: -50.0 for s in seeds})]
    return pd.concat([*frames, rollouts("sac", sac)], ignore_index=True)


SAC_BEST = next(f for f in paper_findings() if f.id == "sac_highest_reward")


def test_between_seed_and_between_episode_spread():
    frame = seed_spread(rollouts("sac", {1: 10.0, 2: 20.0, 3: 30.0}), "main", ["cumulative_reward"])
    row = frame.iloc[0]
    assert (row["policy"], row["seeds"], row["episodes_per_seed"]) == ("sac", 3, 8.0)
    assert row["seed_means"] == pytest.approx([10.0, 20.0, 30.0])
    assert row["between_seed_sd"] == pytest.approx(10.0)
    assert row["between_episode_sd"] == pytest.approx(WITHIN.std(ddof=1))
    assert row["episode_noise_sd"] == pytest.approx(WITHIN.std(ddof=1) / np.sqrt(8))
    assert row["ratio"] == pytest.approx(10.0 / (WITHIN.std(ddof=1) / np.sqrt(8)))
    single = seed_spread(rollouts("sac", {1: 10.0}), "main", ["cumulative_reward"]).iloc[0]
    assert np.isnan(single["between_seed_sd"]) and single["between_episode_sd"] == pytest.approx(WITHIN.std(ddof=1))
    assert seed_spread(rollouts("static", {1: 0.0, 2: 1.0}), "main", ["cumulative_reward"]).empty  # not trained


def test_seed_weights_redraw_learned_seeds_and_keep_every_baseline_rollout():
    metrics = reward_run({1: 0.0, 2: 0.0, 3: 2.0})
    draws = draw_seeds(metrics, n_resamples=50, seed=1)
    assert set(draws.seeds) == {"ppo", "sac", "dqn"} and list(draws.seeds["sac"]) == [1, 2, 3]
    weights = draws.weights(metrics)
    baseline = metrics["policy"].isin(["static", "random", "myopic"]).to_numpy()
    assert (weights[:, baseline] == 1.0).all()
    sac = (metrics["policy"] == "sac").to_numpy()
    assert (weights[:, sac].sum(axis=1) == 3 * EPISODES).all()  # three seeds drawn, EPISODES rollouts each
    first = metrics[sac]["run_seed"].to_numpy()
    assert (weights[:, sac] == draws.counts["sac"][:, first - 1]).all()


def test_the_share_of_seed_resamples_matches_the_exact_bootstrap_probability():
    """SAC seed means 0, 0, 2 against PPO at 1: a resample of three seeds has SAC above PPO exactly
    when it draws seed 3 at least twice: 3 (1/3)^2 (2/3) + (1/3)^3 = 7/27."""
    metrics = reward_run({1: 0.0, 2: 0.0, 3: 2.0})
    share = finding_seed_share(SAC_BEST, RunEstimates(metrics), draw_seeds(metrics, n_resamples=4000, seed=7))
    assert share == pytest.approx(7 / 27, abs=0.025)
    assert seed_decision(share, 3) == "3 seeds cannot decide"


def test_seeds_decide_when_every_resample_agrees():
    metrics = reward_run({1: 5.0, 2: 6.0, 3: 7.0})
    draws = draw_seeds(metrics, n_resamples=300, seed=7)
    assert finding_seed_share(SAC_BEST, RunEstimates(metrics), draws) == 1.0
    assert seed_decision(1.0, 3) == "decided: holds"
    low = reward_run({1: -1.0, 2: -2.0, 3: 0.5})
    assert finding_seed_share(SAC_BEST, RunEstimates(low), draw_seeds(low, n_resamples=300, seed=7)) == 0.0
    assert seed_decision(0.0, 3) == "decided: flips"
    assert seed_decision(1.0, 1) == "1 seed cannot decide (no spread to resample)"


def test_a_finding_the_run_lacks_has_no_share():
    metrics = reward_run({1: 5.0, 2: 6.0, 3: 7.0}).query("policy != 'dqn'")
    assert finding_seed_share(SAC_BEST, RunEstimates(metrics), draw_seeds(metrics, n_resamples=10, seed=1)) is None


def test_ranking_share_compares_only_pairs_the_paper_orders():
    metrics = reward_run({1: 0.0, 2: 0.0, 3: 2.0})
    draws = draw_seeds(metrics, n_resamples=4000, seed=11)
    refs = {p: Ref("main", None, p, "cumulative_reward", "mean") for p in ("ppo", "sac", "dqn")}
    share, run = ranking_seed_share({"sac": 2.0, "ppo": 1.0, "dqn": 0.0}, refs, RunEstimates(metrics), draws)
    assert share == pytest.approx(7 / 27, abs=0.025)
    assert run["sac"] == pytest.approx(2 / 3) and run["ppo"] == pytest.approx(1.0)
    tied, _ = ranking_seed_share({"sac": 1.0, "ppo": 1.0, "dqn": 0.0}, refs, RunEstimates(metrics), draws)
    assert tied == 1.0  # SAC and PPO printed equal: only their order over DQN is checked


def test_the_seed_tables_say_when_seeds_cannot_decide_and_skip_run_directories():
    metrics = reward_run({1: 0.0, 2: 0.0, 3: 2.0})
    for column in ("episode_volume", "physics_violation_rate", "mean_slippage", "artificial_liquidity_MWh"):
        metrics[column] = 0.5
    empty = pd.DataFrame()
    data = ReportData(Path("r"), "paper", metrics, empty, empty, empty)
    options = ReportOptions(n_resamples=2000)
    spread = seed_spread_table(data, options)
    sac = spread.data.query("policy == 'SAC' and metric == 'cumulative_reward'").iloc[0]
    assert sac["between_seed_sd"] == pytest.approx(np.std([0, 0, 2], ddof=1))
    rankings = seed_ranking_table(data, options, draw_seeds(metrics, n_resamples=2000, seed=options.seed))
    reward = rankings.data.set_index("metric").loc["cumulative_reward"]
    assert reward["paper_ranking"] == "SAC > PPO > Myopic > DQN > Static > Random"
    assert reward["run_ranking"] == "PPO > SAC > Myopic > DQN > Static > Random"
    assert reward["seed_share"] == pytest.approx(7 / 27, abs=0.03)  # only SAC over PPO is uncertain
    assert reward["seeds"] == "3 seeds cannot decide"
    run_dir = ReportData(Path("r"), "run", metrics, empty, empty, empty)
    assert seed_spread_table(run_dir, options).reason.startswith("not a paper root")
    assert seed_ranking_table(run_dir, options, None).reason.startswith("not a paper root")
