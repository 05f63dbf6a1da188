"""The Planner/Auditor layer on a second market: the toy stock game of tests/toy_task.py, seen
through a governance view defined only here (no edit to a generic wing)."""

from __future__ import annotations

import copy
import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from solarchain_eval.governance import AgenticOptions, Governance
from solarchain_eval.governance.llm_agent import LLMAgent
from solarchain_eval.governance.planner import episode_context
from solarchain_eval.governance.schemas import AuditPolicy
from solarchain_eval.governance.wrapper import EXTRA_DIAGNOSTICS_KEY, EXTRA_LOG_KEY
from solarchain_eval.llm.client import LLMReply
from solarchain_eval.tasks.governance_view import (
    EpisodeRisk,
    GovernancePrompts,
    GovernanceView,
    NoGovernanceViewError,
    governance_view_of,
)
from toy_task import STEPS, TOY_TASK, SteadyPolicy, ToyEnv

_F32 = np.float32


class ToyCodec:
    """The toy levers are the normalised action itself: [0, 1] each, float32, no cap."""

    lo = (0.0, 0.0, 0.0)
    hi = (1.0, 1.0, 1.0)
    max_total_allocation = 2.0  # release + reorder never exceed it

    def sanitize(self, a0, a1, a2):
        values = np.array([a0, a1, a2], dtype=np.float64)
        if np.isnan(values).any():
            raise ValueError(f"cannot sanitise {values}")
        return tuple(float(v) for v in np.clip(values.astype(_F32), _F32(0.0), _F32(1.0)))

    def decode(self, action):
        return self.sanitize(*np.nan_to_num(np.asarray(action, dtype=_F32).reshape(3)))

    def encode(self, a0, a1, a2):
        return np.array(self.sanitize(a0, a1, a2), dtype=_F32)

    def discrete_table(self, levels):
        values = np.linspace(0.0, 1.0, int(levels), dtype=_F32)
        return [self.decode(p) for p in itertools.product(values, values, values)]


TOY_PROMPTS = GovernancePrompts(
    system="A one-warehouse stock game: release, reorder and margin each hour.",
    planner_instruction="You are the Planner of the stock game.",
    auditor_instruction="You are the Auditor of the stock game.",
    agent_system="You run the warehouse.",
    agent_instruction="Choose this hour's levers.",
    agent_observation_units={"stock": "units on hand", "demand": "units ordered this hour"},
    agent_outcome_units={"reward": "the hour's reward", "shortfall": "units promised beyond stock"},
    lever_descriptions={"release": "share released", "reorder": "share reordered", "margin": "share held back"},
)


def _gap(stock, demand):
    return (stock - demand) / np.maximum(demand, 1e-6)


class ToyView:
    """The toy market's governance view: the gap is (stock - demand) / demand, the oracle a replay."""

    codec = ToyCodec()
    lever_names = ("release", "reorder", "margin")
    observation_names = ("stock", "demand")
    recent_fields = ("reward", "shortfall", "stock")
    prompts = TOY_PROMPTS

    def risk_signals(self, observation):
        stock, demand = (float(v) for v in observation)
        return 0.0, float(_gap(stock, demand)), demand

    def initial_action(self, env):
        return (0.0, 0.0, 0.0)

    def proposal_decoder(self, env, action_mode):
        return self.codec.decode

    def episode_risk(self, env, start_hour):
        demand = np.asarray(env.demand, dtype=np.float64)
        gap = _gap(env.stock, demand)  # against the opening stock: known before the episode
        return EpisodeRisk(
            start_hour=start_hour,
            episode_steps=STEPS,
            penalty_in_reward=True,
            signals=(np.zeros(STEPS), gap, demand),
            statistics={"mean_demand": float(demand.mean()), "opening_stock": float(env.stock)},
        )

    def hour_of_day(self, env, step):
        return step % 24

    def step_hours(self, env, step, info):
        return step, step % 24

    def executed_action(self, info, sent):
        return self.codec.decode(sent)  # the toy env executes the normalised action as given

    def oracle(self, env):
        return lambda executed: copy.deepcopy(env).step(np.asarray(executed, dtype=_F32))[4]

    def outcome_cost(self, outcome):
        return outcome["shortfall"]

    def outcome_reward(self, outcome):
        return outcome["reward"]

    def outcome_values(self, outcome):
        return {"cost": float(outcome["shortfall"]), "reward": float(outcome["reward"])}


class Greedy(SteadyPolicy):
    """Releases everything every hour: the toy market's unsafe proposal."""

    def act(self, observation):
        return np.float32([1.0, 0.2, 0.0])


def run_governed(options, view, seed=3):
    env = ToyEnv()
    with Governance(options, view) as governance:
        policy = governance.wrap(Greedy())
        policy.begin_run(0)
        observation, _ = env.reset(seed=seed)
        policy.begin_episode(env=env, episode=0, run_seed=0, episode_seed=seed, start_hour=0)
        observations, infos, sent = [], [], []
        for _ in range(STEPS):
            observations.append(observation)
            action = policy.act(observation)
            sent.append(action)
            observation, _, _, _, info = env.step(action)
            policy.observe(info)
            infos.append(info)
        return policy.end_episode(), observations, infos, sent


def test_the_toy_view_satisfies_the_protocol_and_the_toy_task_has_none():
    assert isinstance(ToyView(), GovernanceView)
    with pytest.raises(NoGovernanceViewError, match="toy-stock"):
        governance_view_of(TOY_TASK, None)


def test_the_rule_layer_governs_the_toy_market_through_its_view():
    extras, observations, _, sent = run_governed(AgenticOptions(planner="rule", auditor="rule"), ToyView())
    rows = extras[EXTRA_LOG_KEY]
    assert len(rows) == STEPS
    assert list(rows[0]["plan"]["bounds"]) == ["release", "reorder", "margin"]  # the view's levers name the plan
    plan = rows[0]["plan"]["audit_policy"]
    for row, observation, action in zip(rows, observations, sent, strict=True):
        gap = float(_gap(float(observation[0]), float(observation[1])))
        # the gap trigger reads the view's signal, compared in float32 like the solar market's
        assert ("gap" in row["hard_reasons"]) == bool(_F32(gap) < _F32(plan["gap_threshold"]))
        assert row["supply_gap"] == gap
        assert row["executed_action"] == [float(v) for v in action]
        assert row["final_action"] == [float(v) for v in action]
    assert any(row["audited"] for row in rows)
    # the rule auditor's liquidity revision raises the second lever to 0.80 on a shortfall audit
    revised = [r for r in rows if r["decision"] == "revise" and "gap" in r["hard_reasons"]]
    assert revised and all(r["final_action"][1] >= np.float32(0.8) * np.float32(0.9) for r in revised)
    assert extras["agentic_metrics"]["audit_rate"] == sum(r["audited"] for r in rows) / STEPS


def test_the_calibrated_planner_and_oracle_replay_the_toy_market_exactly():
    options = AgenticOptions(planner="calibrated-rule", auditor="oracle", target_audit_rate=0.5, diagnostics=True)
    extras, _, infos, _ = run_governed(options, ToyView())
    diagnostics = extras[EXTRA_DIAGNOSTICS_KEY]
    # the view's oracle replays the executed step bit for bit
    assert [d["final_reward"] for d in diagnostics] == [float(i["reward"]) for i in infos]
    assert [d["final_cost"] for d in diagnostics] == [float(i["shortfall"]) for i in infos]
    audited = [d for d in diagnostics if d["audited"]]
    assert audited and all(d["final_cost"] <= d["bounded_cost"] for d in audited)
    assert any(d["final_cost"] < d["bounded_cost"] for d in audited)  # releasing everything runs short
    assert extras["agentic_metrics"]["planner"] == "calibrated-rule"


def test_episode_context_is_the_views_risk():
    env = ToyEnv()
    env.reset(seed=5)
    context = episode_context(env, 0, ToyView())
    demand = np.asarray(env.demand)
    assert context.min_supply_gap == float(np.min(_gap(5.0, demand)))
    assert context.mean_static_slippage == float(np.mean(demand))
    assert context.statistics == {"mean_demand": float(demand.mean()), "opening_stock": 5.0}


class ScriptedClient:
    """A StructuredLLM stand-in: records the messages, returns the scripted outputs in turn."""

    def __init__(self, outputs):
        self.outputs, self.messages = list(outputs), []
        self.settings = SimpleNamespace(max_retries=0, describe=lambda: {})

    def request(self, messages, output_type, site, invalid_retries=0):
        self.messages.append(messages)
        output = self.outputs.pop(0)
        return LLMReply(
            output_type.model_validate(output) if isinstance(output, dict) else output,
            {"latency_s": 0.0, "input_tokens": 1, "output_tokens": 1, "retries": 0},
        )

    def close(self):
        pass


def test_llm_planner_and_agent_speak_the_views_text_and_levers():
    from solarchain_eval.governance.auditor import LLMAuditor, StepContext
    from solarchain_eval.governance.planner import LLMPlanner
    from solarchain_eval.llm.errors import CallSite

    wide = {"low": 0.0, "high": 1.0}
    plan = {
        "governance_mode": "toy",
        "action_bounds": {"release": {"low": 0.0, "high": 0.4}, "reorder": wide, "margin": wide},
        "audit_policy": AuditPolicy(
            violation_threshold=0.5,
            gap_threshold=-0.5,
            jitter_threshold=3.0,
            slippage_threshold=10.0,
            max_audits_per_episode=2,
            target_audit_rate=0.2,
            cooldown_steps=0,
        ).model_dump(),
        "rationale": "scripted",
    }
    env = ToyEnv()
    env.reset(seed=1)
    client = ScriptedClient([plan])
    view = ToyView()
    levers = tuple(TOY_PROMPTS.lever_descriptions.items())
    outcome = LLMPlanner(client, view.codec, view.prompts, levers).plan(
        episode_context(env, 0, view), CallSite("planner", "p", 0, 0)
    )
    assert client.messages[0][0]["content"] == TOY_PROMPTS.system
    assert client.messages[0][1]["content"].startswith(TOY_PROMPTS.planner_instruction)
    assert (
        '"benchmark_ranges":{"release":[0.0,1.0],"reorder":[0.0,1.0],"margin":[0.0,1.0]'
        in client.messages[0][1]["content"]
    )
    assert '"opening_stock":5' in client.messages[0][1]["content"]
    assert outcome.plan.bounds[0] == (0.0, 0.4)
    assert list(outcome.plan.to_log()["bounds"]) == ["release", "reorder", "margin"]

    verdict = {
        "decision": "revise",
        "final_action": {"release": 0.1, "reorder": 1.5, "margin": 0.0},
        "risk_assessment": {"physics": "low", "liquidity": "high", "jitter": "low", "fairness": "unknown"},
        "reason": "scripted",
    }
    auditor_client = ScriptedClient([verdict])
    step = StepContext(
        step=3,
        hour=3,
        observation={"stock": 1.0, "demand": 2.0},
        violation_rate=0.0,
        supply_gap=-0.5,
        static_slippage=2.0,
        bounded_action=(0.4, 0.5, 0.0),
        previous_action=(0.0, 0.0, 0.0),
        kappa=0.9,
        plan=outcome.plan,
        hard_reasons=("gap",),
        soft_trigger=False,
        recent=None,
    )
    audited = LLMAuditor(auditor_client, view.codec, view.prompts, levers).audit(
        step, CallSite("auditor", "p", 0, 0, 3)
    )
    message = auditor_client.messages[0][1]["content"]
    assert message.startswith(TOY_PROMPTS.auditor_instruction)
    assert '"bounded_proposed_action":{"release":0.4,"reorder":0.5,"margin":0.0}' in message
    assert audited.final_action == (np.float32(0.1), 1.0, 0.0)  # reorder clipped to its range
    assert audited.llm["clipped"][0]["field"] == "final_action.reorder"

    agent_client = ScriptedClient([{"release": 0.25, "reorder": 0.5, "margin": 2.0}])
    agent = LLMAgent(agent_client, view, name="toy-llm")
    assert list(agent.output_type.model_fields) == ["release", "reorder", "margin"]
    with pytest.raises(Exception, match="margin"):  # the schema bounds each lever to its range
        agent.act(np.float32([5.0, 1.0]))
    agent_client.outputs = [{"release": 0.25, "reorder": 0.5, "margin": 1.0}]
    action = agent.act(np.float32([5.0, 1.0]))
    assert action.tolist() == [0.25, 0.5, 1.0]
    messages = agent_client.messages[-1]
    assert messages[0]["content"] == TOY_PROMPTS.agent_system
    assert '"action_ranges":{"release":[0.0,1.0],"reorder":[0.0,1.0],"margin":[0.0,1.0]' in messages[1]["content"]
    assert '"observation":{"stock":5.0,"demand":1.0}' in messages[1]["content"]
