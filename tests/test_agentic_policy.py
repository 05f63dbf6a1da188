"""The policy wrapper: any base policy (discrete too), approve-only and default components,
forwarded hooks, and an agentic run directory written by the evaluation runner."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.evaluation.rollout import run_policy
from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation
from solarchain_eval.governance import AgenticOptions, Governance
from solarchain_eval.governance.planner import episode_context
from solarchain_eval.market.baselines import make_baseline


class FixedIndexPolicy:
    """A discrete policy (like DQN) that always picks grid point ``index``; records hooks."""

    action_mode = "discrete"

    def __init__(self, index: int, name: str = "dqn") -> None:
        self.index, self.name = index, name
        self.calls: list[str] = []

    def begin_run(self, run_seed: int) -> None:
        self.calls.append("run")

    def begin_episode(self, **kwargs) -> None:
        self.calls.append("begin")

    def observe(self, info) -> None:
        self.calls.append("observe")

    def end_episode(self) -> dict:
        self.calls.append("end")
        return {"base_extra": 1}

    def act(self, observation):
        return np.int64(self.index)


def run(data_dir, policy, options=AgenticOptions(), episodes=2, seed=3):
    config = BenchmarkConfig()
    env = SolarChainEnv(data_dir, config=config)
    with Governance(options, config.market) as governance:
        return env, list(run_policy(env, governance.wrap(policy), setting="llm", run_seeds=[seed], episodes=episodes))


def test_discrete_base_policy_is_decoded_with_the_grid_and_hooks_are_forwarded(tiny_dataset):
    base = FixedIndexPolicy(124)  # (1, 1, 1): α = 0.65, ℓ = 0.95 -> scaled to the 0.98 cap
    env, results = run(tiny_dataset, base)
    table = env.codec.discrete_table(env.config.discrete_levels)
    for result in results:
        assert result.policy == "dqn" and result.extras["base_extra"] == 1
        for row in result.extras["agentic_log"]:
            assert row["proposed_action"] == [float(v) for v in table[124]]
    assert (
        base.calls[:3] == ["run", "begin", "observe"]
        and base.calls.count("observe") == 48
        and base.calls.count("end") == 2
    )


def test_executed_action_is_the_reencoded_final_action(tiny_dataset):
    env, results = run(tiny_dataset, make_baseline("random"), episodes=3)
    for row in (r for result in results for r in result.extras["agentic_log"]):
        expected = env.codec.decode(env.codec.encode(*row["final_action"]))
        assert row["executed_action"] == list(expected)
        # re-encoding may move it by an ulp; the log keeps the pre-encoding final action
        assert np.allclose(row["executed_action"], row["final_action"], rtol=0, atol=1e-7)


def test_approve_only_auditor_keeps_the_bounded_action(tiny_dataset):
    _, results = run(
        tiny_dataset, make_baseline("random"), AgenticOptions(planner="rule", auditor="approve-only"), episodes=4
    )
    audited = [r for result in results for r in result.extras["agentic_log"] if r["audited"]]
    assert audited
    for result in results:
        assert result.extras["agentic_metrics"]["revision_rate"] == 0.0
        for row in result.extras["agentic_log"]:
            assert row["final_action"] == row["bounded_action"]
            assert row["decision"] == ("approve" if row["audited"] else None)


def test_default_planner_uses_full_bounds(tiny_dataset):
    env, results = run(tiny_dataset, make_baseline("myopic"), AgenticOptions(planner="default", auditor="rule"))
    plan = results[0].extras["agentic_log"][0]["plan"]
    assert plan["governance_mode"] == "default_full_bounds"
    assert plan["bounds"] == {"reward_ratio": [0.05, 0.65], "liquidity_ratio": [0.2, 0.95], "burn_rate": [0.0, 0.2]}
    assert results[0].extras["agentic_metrics"]["planner"] == "default"
    for row in results[0].extras["agentic_log"]:  # full bounds: bounding changes nothing
        assert row["bounded_action"] == row["proposed_action"]


def test_episode_context_statistics_come_from_the_episode_hours(published_dir):
    env = SolarChainEnv(published_dir)
    t = env.table
    context = episode_context(env, 48)
    hours = slice(48, 72)
    gap = (t.verified_mwh[hours] - t.demand_mwh[hours]) / np.maximum(t.demand_mwh[hours], 1e-6)
    assert context.max_violation_rate == t.raw_violation_rate[hours].max()
    assert context.min_supply_gap == gap.min()
    assert context.mean_static_slippage == np.mean(t.static_slippage[hours])


def test_an_agentic_run_writes_a_complete_run_dir(tiny_dataset, tmp_path):
    policy = FixedIndexPolicy(62, name="fixed")
    spec = EvaluationSpec(
        policies=[policy],
        run_seeds=[11],
        episodes=2,
        data_dir=tiny_dataset,
        no_physics_penalty=True,
        agentic=AgenticOptions(),
    )
    assert spec.setting == "llm_no_physics"
    outcome = run_evaluation(spec, tmp_path / "unit")
    unit = tmp_path / "unit"
    metrics = pd.read_csv(unit / "metrics.csv")
    assert list(metrics["policy"]) == ["fixed", "fixed"] and set(metrics["setting"]) == {"llm_no_physics"}
    assert list(metrics["episode_seed"]) == [11, 12]
    lines = (unit / "agentic_logs.jsonl").read_text().splitlines()
    assert len(lines) == 48 and json.loads(lines[0])["setting"] == "llm_no_physics"
    meta = json.loads((unit / "run_metadata.json").read_text())
    assert (
        meta["policies"] == ["fixed"] and meta["agentic"]["auditor"] == "rule" and meta["config"]["no_physics_penalty"]
    )
    assert len(outcome.results) == 2


@pytest.mark.parametrize("name", ["static", "myopic"])
def test_neutral_layer_reproduces_the_plain_run(tiny_dataset, name):
    """Full bounds + approve-only change nothing: a policy whose actions survive re-encoding
    (static, myopic) gives bit-identical per-step records with and without the layer."""
    config = BenchmarkConfig()
    env = SolarChainEnv(tiny_dataset, config=config)
    plain = list(run_policy(env, make_baseline(name), setting="main", run_seeds=[4], episodes=4))
    _, governed = run(
        tiny_dataset, make_baseline(name), AgenticOptions(planner="default", auditor="approve-only"), episodes=4, seed=4
    )
    for a, b in zip(plain, governed, strict=True):
        assert a.steps == b.steps and a.metrics == b.metrics
        assert b.extras["agentic_metrics"]["modification_rate"] == 0.0
