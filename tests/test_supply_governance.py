"""The Planner/Auditor layer on the supply-chain market, through the market's governance view."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

import solarchain_eval
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.governance import AgenticOptions, Governance
from solarchain_eval.governance.auditor import LLMAuditor
from solarchain_eval.governance.calibrated import calibrated_thresholds
from solarchain_eval.governance.llm_agent import LLMAgent
from solarchain_eval.governance.planner import LLMPlanner
from solarchain_eval.governance.schemas import AuditPolicy
from solarchain_eval.governance.wrapper import EXTRA_LOG_KEY
from solarchain_eval.llm.client import LLMReply
from solarchain_eval.supply.env import INITIAL_ACTION, OBS, SupplyChainEnv
from solarchain_eval.supply.governance_prompts import AGENT_SYSTEM, AUDITOR_INSTRUCTION, PLANNER_INSTRUCTION, SYSTEM
from solarchain_eval.supply.governance_view import SupplyGovernanceView, static_forecast
from solarchain_eval.tasks import get_task
from solarchain_eval.tasks.governance_view import GovernanceView, governance_view_of
from supply_fixtures import supply_dir, supply_table  # noqa: F401

LEVERS = ["supplier_incentive", "release_ratio", "demand_damping"]
_F32 = np.float32


def release_all(observation):
    """Releases every reported unit and orders no production: runs the stock down onto phantom stock."""
    return np.float32([0.0, 1.0, 0.0])


def _env(table, **updates):
    return SupplyChainEnv(config=BenchmarkConfig().with_updates(**updates), table=table)


def _view():
    view = governance_view_of(get_task("supply-chain"), None)
    assert isinstance(view, SupplyGovernanceView) and isinstance(view, GovernanceView)
    return view


def test_the_risk_signals_are_the_phantom_share_the_stock_gap_and_the_backlog(supply_table):  # noqa: F811
    view, env = _view(), _env(supply_table)
    obs, _ = env.reset(seed=4)
    seen_phantom = seen_backlog = False
    for _ in range(env.episode_steps):
        violation, gap, slippage = view.risk_signals(obs)
        on_hand, reported = float(obs[OBS["on_hand_days"]]), float(obs[OBS["reported_stock_days"]])
        demand = float(obs[OBS["orders_days"]]) + float(obs[OBS["backlog_days"]])
        assert violation == max(reported - on_hand, 0.0) / max(reported, 1e-6)
        assert gap == (on_hand - demand) / max(demand, 1e-6)
        assert slippage == float(obs[OBS["backlog_days"]])
        seen_phantom |= violation > 0
        seen_backlog |= slippage > 0
        obs, *_ = env.step(release_all(obs))
    assert seen_phantom and seen_backlog  # the signals are not trivially zero on this data


def test_the_episode_risk_is_the_static_actions_forecast_and_leaves_the_env_alone(supply_table):  # noqa: F811
    view, env, twin = _view(), _env(supply_table), _env(supply_table)
    obs, info = env.reset(seed=11)
    twin.reset(seed=11)
    risk = view.episode_risk(env, info["episode_start_hour"])
    # the static action held from the reset state: the forecast is what the static policy then observes
    observed = []
    for _ in range(env.episode_steps):
        observed.append(view.risk_signals(obs))
        obs, *_ = env.step(np.float32(INITIAL_ACTION))
    for i, signal in enumerate(risk.signals):
        assert signal.tolist() == [row[i] for row in observed]
    assert risk.statistics["max_phantom_share"] == max(row[0] for row in observed) > 0
    assert risk.penalty_in_reward and risk.episode_steps == 24 and risk.start_hour == info["episode_start_hour"]
    # the forecast ran on a copy: the twin, never forecast, takes the same steps
    env.reset(seed=11)
    static_forecast(env)
    for _ in range(5):
        a, b = env.step(np.float32([0.6, 0.9, 0.1])), twin.step(np.float32([0.6, 0.9, 0.1]))
        assert a[0].tolist() == b[0].tolist() and a[4]["reward"] == b[4]["reward"]
    ablated = _env(supply_table, no_physics_penalty=True)
    ablated.reset(seed=11)
    assert not view.episode_risk(ablated, 0).penalty_in_reward


@pytest.mark.parametrize("penalty", [True, False])
def test_the_oracle_replays_the_executed_step_exactly(supply_table, penalty):  # noqa: F811
    view = _view()
    env = _env(supply_table, no_physics_penalty=not penalty)
    rng = np.random.default_rng(3)
    unsafe_steps = 0
    for episode in range(3):
        env.reset(seed=episode)
        oracle = view.oracle(env)
        for step in range(env.episode_steps):
            sent = view.codec.encode(*rng.uniform(-0.2, 1.2, 3)) if step % 3 else release_all(None)
            executed = view.codec.decode(sent)
            other = oracle((1.0, 1.0, 0.0))  # another action first: the oracle must not move the env
            outcome = oracle(executed)
            _, reward, _, _, info = env.step(sent)
            assert view.executed_action(info, sent) == executed
            assert view.outcome_reward(outcome) == reward == info["reward"]
            assert outcome.outcome.unsafe_units == info["unsafe_units"]
            assert view.outcome_cost(outcome) == info["cost"]
            values = view.outcome_values(outcome)
            assert values["unsafe_units"] == info["unsafe_units"]
            assert values["phantom_fill_volume_units"] == info["phantom_fill_volume_units"]
            assert values["filled_units"] == info["filled_units"]
            assert values["price_index"] == info["price_index"]
            assert other.outcome.filled_units >= outcome.outcome.filled_units
            unsafe_steps += info["unsafe_units"] > 0
    assert unsafe_steps >= 3  # the replay is checked on steps that ship on phantom stock


def test_evaluate_governs_the_supply_market_with_the_rule_layer(supply_dir, tmp_path):  # noqa: F811
    out = tmp_path / "run"
    evaluation = solarchain_eval.evaluate(
        ["static", "myopic"], task="supply-chain", agentic=True, seeds=[1], episodes=2, data=supply_dir, out=out
    )
    metrics = evaluation.metrics
    assert set(metrics["setting"]) == {"llm"} and len(metrics) == 4
    assert set(metrics["planner"]) == {"rule"} and set(metrics["auditor"]) == {"rule"}
    for column in ("audit_rate", "revision_rate", "hard_trigger_rate", "physics_trigger_rate", "plan_audit_budget"):
        assert metrics[column].notna().all()
    assert metrics["audit_rate"].gt(0).any()
    logs = [json.loads(line) for line in (out / "agentic_logs.jsonl").read_text().splitlines()]
    assert len(logs) == 4 * 24
    assert all(list(row["plan"]["bounds"]) == LEVERS for row in logs)
    for row in logs:  # the hard triggers read the supply signals against the plan's thresholds
        policy = row["plan"]["audit_policy"]
        assert ("violation" in row["hard_reasons"]) == bool(
            _F32(row["raw_violation_rate"]) > _F32(policy["violation_threshold"])
        )
        assert ("slippage" in row["hard_reasons"]) == bool(
            _F32(row["static_slippage"]) > _F32(policy["slippage_threshold"])
        )
        # a step is a day of an episode starting on a Monday: "hour" is the day of the week
        assert row["hour"] == row["step"] % 7 and row["absolute_hour"] - row["step"] in set(metrics["start_hour"])
    # the diagnostics' replay of each executed step is the step the run recorded
    diagnostics = pd.read_csv(out / "governance_diagnostics.csv")
    actions = pd.read_csv(out / "actions.csv")
    keys = ["policy", "run_seed", "episode", "step"]
    merged = diagnostics.merge(actions, on=keys, validate="one_to_one")
    assert len(merged) == len(actions) == 4 * 24
    assert merged["final_reward"].tolist() == merged["reward"].tolist()
    assert merged["final_cost"].tolist() == merged["cost"].tolist()
    assert merged["final_unsafe_units"].tolist() == merged["unsafe_units"].tolist()


def test_the_calibrated_planner_and_the_oracle_auditor_run_on_the_supply_market(supply_dir, tmp_path):  # noqa: F811
    options = AgenticOptions(planner="calibrated-rule", auditor="oracle", target_audit_rate=0.25)
    out = tmp_path / "run"
    evaluation = solarchain_eval.evaluate(
        ["static", release_all], task="supply-chain", agentic=options, seeds=[2], episodes=2, data=supply_dir, out=out
    )
    metrics = evaluation.metrics.set_index(["policy", "episode"])
    diagnostics = pd.read_csv(out / "governance_diagnostics.csv")
    # the static policy sees exactly the forecast the planner calibrated on: its audit rate is the
    # rate the calibration gives on the signals the run observed
    logs = [json.loads(line) for line in (out / "agentic_logs.jsonl").read_text().splitlines()]
    for episode in (0, 1):
        rows = [row for row in logs if row["policy"] == "static" and row["episode"] == episode]
        observed = tuple(
            np.array([row[key] for row in rows], dtype=np.float32)
            for key in ("raw_violation_rate", "supply_gap", "static_slippage")
        )
        thresholds, rate = calibrated_thresholds(observed, 0.25)
        assert metrics.loc[("static", episode), "audit_rate"] == rate > 0
        policy = rows[0]["plan"]["audit_policy"]
        assert (policy["violation_threshold"], policy["gap_threshold"], policy["slippage_threshold"]) == thresholds
    # the oracle revises the greedy policy's audited steps to a lower cost, never a higher one
    audited = diagnostics[(diagnostics["policy"] == "release_all") & diagnostics["audited"]]
    assert len(audited) > 0
    assert (audited["final_cost"] <= audited["bounded_cost"]).all()
    assert (audited["final_cost"] < audited["bounded_cost"]).any()
    assert (audited["bounded_reward"] - audited["final_reward"] <= 0.05 + 1e-12).all()
    assert set(metrics["planner"]) == {"calibrated-rule"} and set(metrics["auditor"]) == {"oracle"}


class ScriptedClient:
    """A StructuredLLM stand-in: records the messages and answers every call with ``output``."""

    def __init__(self, output):
        self.output, self.messages = output, []
        self.settings = SimpleNamespace(max_retries=0, describe=lambda: {})

    def request(self, messages, output_type, site, invalid_retries=0):
        self.messages.append(messages)
        meta = {"latency_s": 0.0, "input_tokens": 1, "output_tokens": 1, "retries": 0}
        return LLMReply(output_type.model_validate(self.output), meta)

    def close(self):
        pass


def test_the_llm_planner_auditor_and_agent_read_the_supply_text_and_levers(supply_table):  # noqa: F811
    view = _view()
    levers = tuple(view.prompts.lever_descriptions.items())
    wide = {"low": 0.0, "high": 1.0}
    plan = {
        "governance_mode": "scripted",
        "action_bounds": {
            "supplier_incentive": wide,
            "release_ratio": {"low": 0.0, "high": 0.9},
            "demand_damping": wide,
        },
        "audit_policy": AuditPolicy(
            violation_threshold=0.0,
            gap_threshold=-1.0,
            jitter_threshold=3.0,
            slippage_threshold=10.0,
            max_audits_per_episode=24,
            target_audit_rate=1.0,
            cooldown_steps=0,
        ).model_dump(),
        "rationale": "scripted",
    }
    revision = {"supplier_incentive": 0.5, "release_ratio": 0.4, "demand_damping": 0.1}
    verdict = {
        "decision": "revise",
        "final_action": revision,
        "risk_assessment": {"physics": "high", "liquidity": "low", "jitter": "low", "fairness": "unknown"},
        "reason": "scripted",
    }
    planner_client, auditor_client = ScriptedClient(plan), ScriptedClient(verdict)
    env = _env(supply_table)
    with Governance(AgenticOptions(), view) as governance:
        governance.planner = LLMPlanner(planner_client, view.codec, view.prompts, levers)
        governance.auditor = LLMAuditor(auditor_client, view.codec, view.prompts, levers)
        policy = governance.wrap(get_task("supply-chain").baselines()["static"](None))
        policy.begin_run(0)
        obs, info = env.reset(seed=5)
        policy.begin_episode(env=env, episode=0, run_seed=0, episode_seed=5, start_hour=info["episode_start_hour"])
        executed = []
        for _ in range(env.episode_steps):
            obs, _, _, _, info = env.step(policy.act(obs))
            policy.observe(info)
            executed.append([info[name] for name in LEVERS])
        rows = policy.end_episode()[EXTRA_LOG_KEY]
    (planner_messages,) = planner_client.messages
    assert planner_messages[0]["content"] == SYSTEM and "phantom stock" in SYSTEM
    user = planner_messages[1]["content"]
    assert user.startswith(PLANNER_INSTRUCTION)
    assert (
        '"benchmark_ranges":{"supplier_incentive":[0.0,1.0],"release_ratio":[0.0,1.0],"demand_damping":[0.0,1.0]'
        in user
    )
    assert '"max_phantom_share":' in user and '"min_stock_gap":' in user
    assert list(rows[0]["plan"]["bounds"]) == LEVERS and rows[0]["plan"]["bounds"]["release_ratio"] == [0.0, 0.9]
    audited = [row for row in rows if row["audited"]]
    assert len(auditor_client.messages) == len(audited) > 0
    first = auditor_client.messages[0][1]["content"]
    assert auditor_client.messages[0][0]["content"] == SYSTEM and first.startswith(AUDITOR_INSTRUCTION)
    assert '"bounded_proposed_action":{"supplier_incentive":0.25,"release_ratio":0.75,"demand_damping":0.05}' in first
    assert '"on_hand_days":' in first and '"reported_stock_days":' in first
    # the episode starts on a Monday: the auditor's "hour" is the day of the week
    for row, messages in zip(audited, auditor_client.messages, strict=True):
        assert f'"step":{row["step"]},"hour_of_day":{row["step"] % 7},' in messages[1]["content"]
    assert max(row["step"] for row in audited) >= 7
    later = auditor_client.messages[-1][1]["content"]
    assert all(f'"{name}":' in later for name in ("phantom_fill_volume_units", "unsafe_units", "backlog_units"))
    # an audited day executes the auditor's revision; every audit was called by the phantom share
    for row, levers_executed in zip(rows, executed, strict=True):
        if row["audited"]:
            assert levers_executed == [float(_F32(revision[name])) for name in LEVERS]
            assert row["hard_reasons"] == ["violation"] and row["raw_violation_rate"] > 0

    agent_client = ScriptedClient({"supplier_incentive": 0.3, "release_ratio": 0.6, "demand_damping": 0.2})
    agent = LLMAgent(agent_client, view, name="supply-llm")
    assert list(agent.output_type.model_fields) == LEVERS
    obs, _ = env.reset(seed=5)
    assert agent.act(obs).tolist() == [float(_F32(v)) for v in (0.3, 0.6, 0.2)]
    system, message = (m["content"] for m in agent_client.messages[0])
    assert system == AGENT_SYSTEM and "phantom stock" in system
    assert (
        '"action_ranges":{"supplier_incentive":[0.0,1.0],"release_ratio":[0.0,1.0],"demand_damping":[0.0,1.0]'
        in message
    )
    on_hand = float(f"{obs[OBS['on_hand_days']]:.6g}")
    assert f'"on_hand_days":{on_hand}' in message


def test_a_discrete_proposal_decodes_as_the_discrete_env_executes_it(supply_table):  # noqa: F811
    view = _view()
    discrete = _env(supply_table, action_mode="discrete")
    decode = view.proposal_decoder(discrete, "discrete")
    discrete.reset(seed=1)
    for index in (0, 7, 62, 124, np.int64(93)):
        info = discrete.step(index)[4]
        assert decode(index) == tuple(info[name] for name in LEVERS)
    assert view.codec.decode(view.codec.encode(*decode(93))) == decode(93)  # a grid point survives the round trip
    with pytest.raises(ValueError, match="action mode"):
        view.proposal_decoder(discrete, "binary")
