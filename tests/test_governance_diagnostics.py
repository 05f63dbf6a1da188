"""Counterfactual step records, controls and the calibrated planner (docs/governance.md)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.evaluation.records import diagnostics_frame
from solarchain_eval.evaluation.rollout import run_policy
from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation
from solarchain_eval.governance import AgenticOptions, Governance
from solarchain_eval.governance.auditor import RuleAuditor, rule_revision
from solarchain_eval.governance.calibrated import calibrated_thresholds
from solarchain_eval.governance.controls import OracleAuditor, SchedulerControls
from solarchain_eval.governance.counterfactual import CounterfactualEvaluator, step_cost
from solarchain_eval.governance.planner import episode_context
from solarchain_eval.market.baselines import make_baseline

OUTCOME_COLUMNS = {
    "violation_rate": "physics_violation_rate",
    "unsafe_backed_MWh": "unsafe_backed_MWh",
    "cost": "cost",
    "reward": "reward",
    "matched_energy_MWh": "matched_energy_MWh",
    "slippage": "slippage",
    "artificial_liquidity_MWh": "artificial_liquidity_MWh",
    "token_price": "token_price",
}


def governed(data_dir, options, policy="random", episodes=3, seed=5, governance_hook=None):
    config = BenchmarkConfig()
    env = SolarChainEnv(data_dir, config=config)
    with Governance(options, config.market) as governance:
        if governance_hook is not None:
            governance_hook(governance)
        results = list(
            run_policy(env, governance.wrap(make_baseline(policy)), setting="llm", run_seeds=[seed], episodes=episodes)
        )
    return env, results


def test_counterfactual_of_the_executed_action_is_the_logged_step_exactly(tiny_dataset):
    _, results = governed(tiny_dataset, AgenticOptions(planner="calibrated-rule", diagnostics=True))
    frame = diagnostics_frame(results)
    assert len(frame) == sum(r.n_steps for r in results)
    for suffix, info_key in OUTCOME_COLUMNS.items():
        executed = np.concatenate([np.asarray(r.steps[info_key], dtype=float) for r in results])
        assert np.array_equal(frame[f"final_{suffix}"].to_numpy(), executed), suffix
    # Unaudited steps execute ā: their ā and final outcomes coincide bit for bit.
    unaudited = ~frame["audited"].astype(bool)
    assert unaudited.any()
    for suffix in OUTCOME_COLUMNS:
        assert np.array_equal(frame.loc[unaudited, f"final_{suffix}"], frame.loc[unaudited, f"bounded_{suffix}"])


def test_approve_only_has_zero_deltas_and_rule_revisions_do_not(tiny_dataset):
    _, results = governed(tiny_dataset, AgenticOptions(auditor="approve-only", diagnostics=True))
    frame = diagnostics_frame(results)
    assert frame["audited"].any()
    assert (frame["final_cost"] - frame["bounded_cost"]).abs().max() == 0.0
    assert (frame["final_reward"] - frame["bounded_reward"]).abs().max() == 0.0
    _, results = governed(tiny_dataset, AgenticOptions(auditor="rule", diagnostics=True))
    frame = diagnostics_frame(results)
    revised = frame["decision"] == "revise"
    assert revised.any() and (frame.loc[revised, "final_reward"] != frame.loc[revised, "bounded_reward"]).any()
    # cost never goes below the least-backing action's
    assert (frame[["proposal_cost", "bounded_cost", "final_cost"]].min(axis=1) >= frame["least_cost"]).all()


def test_counterfactual_step_leaves_the_env_untouched(tiny_dataset):
    config = BenchmarkConfig()
    plain, probed = SolarChainEnv(tiny_dataset, config=config), SolarChainEnv(tiny_dataset, config=config)
    plain.reset(seed=11)
    probed.reset(seed=11)
    action = np.array([0.7, 0.2, 0.4], dtype=np.float32)
    for _ in range(5):
        executed = probed.decode_action(action)
        predicted = probed.counterfactual_step(executed)
        probed.counterfactual_step((0.05, 0.2, 0.0))  # any other action, evaluated and discarded
        _, reward_a, _, _, info_a = plain.step(action)
        _, reward_b, _, _, info_b = probed.step(action)
        assert reward_a == reward_b == predicted.reward
        assert info_a["cost"] == info_b["cost"] == step_cost(predicted)
        assert info_a["token_price"] == info_b["token_price"] == predicted.token_price


def test_diagnostics_leave_every_other_run_file_byte_identical(tiny_dataset, tmp_path):
    def run(name, diagnostics):
        spec = EvaluationSpec(
            policies=["static", "random", "myopic"],
            run_seeds=[3],
            episodes=2,
            data_dir=tiny_dataset,
            agentic=AgenticOptions(auditor="rule", diagnostics=diagnostics),
        )
        return run_evaluation(spec, tmp_path / name, command=["test"])

    without, with_ = run("without", False), run("with", True)
    assert "governance_diagnostics.csv" in with_.files and "governance_diagnostics.csv" not in without.files
    for name in ("metrics.csv", "actions.csv", "city_hour_policy.csv", "agentic_logs.jsonl", "summary.json"):
        assert (tmp_path / "without" / name).read_bytes() == (tmp_path / "with" / name).read_bytes(), name
    frame = pd.read_csv(tmp_path / "with" / "governance_diagnostics.csv")
    actions = pd.read_csv(tmp_path / "with" / "actions.csv")
    assert np.array_equal(frame["final_reward"].to_numpy(), actions["reward"].to_numpy())  # CSV round-trips exactly


class ComparingAuditor(RuleAuditor):
    """Acts as the rule auditor; on each audited step checks the oracle against it and ā."""

    def __init__(self, codec, oracle):
        super().__init__(codec)
        self.oracle, self.checked = oracle, 0

    def audit(self, context, site):
        evaluate = context.counterfactual
        action, cost, reward = self.oracle.best(context)
        # fast path (grid pre-encoded, evaluator.executed) == the plain evaluator call per action
        plain = dataclasses.replace(context, counterfactual=lambda a: evaluate(a))
        assert self.oracle.best(plain) == (action, cost, reward)
        assert cost == step_cost(evaluate(action))
        rule_action, _ = rule_revision(context, self.codec)
        base, rule = evaluate(context.bounded_action), evaluate(rule_action)
        assert cost <= step_cost(base)
        if not math.isfinite(self.oracle.reward_loss) or base.reward - rule.reward <= self.oracle.reward_loss:
            assert cost <= step_cost(rule)
        if not math.isfinite(self.oracle.reward_loss):  # unbounded: the least cost of any action
            assert cost == step_cost(evaluate(evaluate.least_action))
        else:
            assert reward >= base.reward - self.oracle.reward_loss
        self.checked += 1
        return super().audit(context, site)


@pytest.mark.parametrize("reward_loss", [math.inf, 0.05, 0.0])
def test_oracle_costs_no_more_than_the_rule_auditor_on_the_same_steps(tiny_dataset, reward_loss):
    checkers = []

    def install(governance):
        governance.auditor = ComparingAuditor(
            governance.auditor.codec, OracleAuditor(governance.auditor.codec, reward_loss)
        )
        checkers.append(governance.auditor)

    governed(tiny_dataset, AgenticOptions(auditor="rule"), policy="random", episodes=2, governance_hook=install)
    assert checkers[0].checked > 0


def test_oracle_auditor_runs_and_never_raises_cost(tiny_dataset):
    _, results = governed(tiny_dataset, AgenticOptions(auditor="oracle", diagnostics=True), episodes=2)
    frame = diagnostics_frame(results)
    audited = frame["audited"].astype(bool)
    assert (frame.loc[audited, "final_cost"] <= frame.loc[audited, "bounded_cost"]).all()
    assert (frame.loc[audited, "final_reward"] >= frame.loc[audited, "bounded_reward"] - 0.05 - 1e-12).all()
    assert (frame["decision"] == "revise").any()


def test_random_auditor_audits_the_matched_count_deterministically(tiny_dataset):
    options = AgenticOptions(planner="default", auditor="random", random_audit_rate=0.25, diagnostics=True)
    _, first = governed(tiny_dataset, options, episodes=3)
    _, second = governed(tiny_dataset, options, episodes=3)
    chosen = []
    for a, b in zip(first, second, strict=True):
        steps_a = [row["step"] for row in a.extras["agentic_log"] if row["audited"]]
        assert steps_a == [row["step"] for row in b.extras["agentic_log"] if row["audited"]]
        assert len(steps_a) == 6 and a.extras["agentic_metrics"]["audit_rate"] == 0.25
        chosen.append(tuple(steps_a))
    assert len(set(chosen)) > 1  # a fresh draw per episode
    per_policy = AgenticOptions(auditor="random", random_audit_rate={"random": 0.5, "other": 0.1})
    _, results = governed(tiny_dataset, per_policy, episodes=2)
    assert all(r.extras["agentic_metrics"]["audit_rate"] == 0.5 for r in results)


def test_always_audit_audits_every_step(tiny_dataset):
    _, results = governed(tiny_dataset, AgenticOptions(planner="default", auditor="always-audit"), episodes=2)
    assert all(r.extras["agentic_metrics"]["audit_rate"] == 1.0 for r in results)
    assert all(r.extras["agentic_metrics"]["auditor"] == "always-audit" for r in results)


@pytest.mark.parametrize("target", [0.25, 0.5])
def test_calibrated_planner_reaches_its_target_audit_rate(tiny_dataset, target):
    options = AgenticOptions(planner="calibrated-rule", auditor="approve-only", target_audit_rate=target)
    env, results = governed(tiny_dataset, options, episodes=4)
    rates = []
    for r in results:
        context = episode_context(env, r.start_hour)
        _, predicted = calibrated_thresholds(context.hourly_signals, target)
        rate = r.extras["agentic_metrics"]["audit_rate"]
        assert rate == predicted  # soft trigger off: exactly the calibrated hard-trigger rate
        assert r.extras["agentic_metrics"]["planner"] == "calibrated-rule"
        rates.append(rate)
    # Ties (every night hour has gap -1) make the reachable rates coarse: within 0.1 of the target.
    assert abs(float(np.mean(rates)) - target) <= 0.1


def test_calibrated_thresholds_on_hand_made_signals():
    slippage = np.arange(24, dtype=np.float32) / 4  # 0, 0.25, ..., 5.75: one step per level
    zeros = np.zeros(24, dtype=np.float32)
    gap = np.full(24, 0.5, dtype=np.float32)
    (tv, tg, ts), rate = calibrated_thresholds((zeros, gap, slippage), 0.25)
    assert rate == 0.25 and ts == 4.25 and (tv, tg) == (0.0, 0.0)  # six steps above 4.25; ν, gap never fire


@pytest.mark.parametrize(
    ("triggers", "allowed"),
    [("soft", set()), ("slippage", {"slippage"}), ("violation", {"violation"}), ("hard", None)],
)
def test_trigger_ablations_keep_only_their_triggers(tiny_dataset, triggers, allowed):
    options = AgenticOptions(controls=SchedulerControls(triggers=triggers))
    _, results = governed(tiny_dataset, options, episodes=2)
    rows = [row for r in results for row in r.extras["agentic_log"]]
    if allowed is not None:
        assert all(set(row["hard_reasons"]) <= allowed for row in rows)
    if triggers != "soft":
        assert not any(row["soft_trigger"] for row in rows)
    if triggers == "soft":
        assert not any(row["hard_trigger"] for row in rows)
        assert any(row["soft_trigger"] for row in rows)


def test_budget_and_cooldown_overrides(tiny_dataset):
    options = AgenticOptions(
        planner="default", controls=SchedulerControls(triggers="soft", max_audits=2, cooldown_steps=0)
    )
    _, results = governed(tiny_dataset, options, episodes=3)
    for r in results:
        assert r.extras["agentic_metrics"]["plan_audit_budget"] == 2
        assert sum(row["audited"] for row in r.extras["agentic_log"]) <= 2


def test_evaluator_memoises_and_matches_the_env(tiny_dataset):
    env = SolarChainEnv(tiny_dataset, config=BenchmarkConfig())
    env.reset(seed=2)
    evaluate = CounterfactualEvaluator(env)
    first = evaluate((0.3, 0.5, 0.1))
    assert evaluate((0.3, 0.5, 0.1)) is first
    executed = env.codec.decode(env.codec.encode(0.3, 0.5, 0.1))
    assert env.counterfactual_step(executed) == first


def test_diagnostics_csv_is_what_pandas_writes(tiny_dataset):
    from solarchain_eval.evaluation.records import diagnostics_csv

    _, results = governed(tiny_dataset, AgenticOptions(planner="calibrated-rule", diagnostics=True), episodes=2)
    assert diagnostics_csv(results) == diagnostics_frame(results).to_csv(index=False)
