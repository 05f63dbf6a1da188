"""One request per agent (agents/request.py), one builder (agents/build.py), for every kind.

Each kind is built three ways and driven through the same episode: directly from the pieces the
evaluation used to assemble by hand (the market's baseline, the loaded class, the SB3 model, the
HTTP client, ``open_llm_agent``), through ``build_agents(agent_requests(...))``, and through the
runner's ``make_policies(EvaluationSpec(...))``. The three must take the same actions on the same
observations, under the same name, action mode and access label.
"""

from __future__ import annotations

import sys
import textwrap
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest

from agent_server import ScriptedAgentServer
from fake_openai import FakeOpenAI, ok
from solarchain_eval.agents.adapters import SB3ModelAgent, as_agent
from solarchain_eval.agents.base import access_label
from solarchain_eval.agents.build import build_agents
from solarchain_eval.agents.http_agent import HttpAgent
from solarchain_eval.agents.registry import EXTRA_POLICIES, make_policy
from solarchain_eval.agents.request import AgentContext, AgentRequest, agent_request, agent_requests
from solarchain_eval.agents.specs import AgentSpecError
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.data.table import load_table
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.evaluation.rollout import run_policy
from solarchain_eval.evaluation.runner import EvaluationSpec, make_policies
from solarchain_eval.governance import LLMOptions
from solarchain_eval.governance.llm_agent import open_llm_agent
from solarchain_eval.llm import resolve_llm_settings
from solarchain_eval.market.baselines import make_baseline

SEED = 11
CONFIG = BenchmarkConfig()
LEVERS = ("reward_ratio", "liquidity_ratio", "burn_rate")

AGENT_MODULE = textwrap.dedent(
    """
    import numpy as np


    class Drifting:
        # stateful: each action depends on the observation and on how many steps it took
        def __init__(self, scale=0.1):
            self.scale, self.steps = scale, 0

        def begin_episode(self, **context):
            self.steps = 0

        def act(self, observation):
            self.steps += 1
            base = 0.3 * float(np.tanh(observation[0])) * self.scale  # scale <= 1 keeps it in [0, 1]
            return np.array([0.4 + base, 0.5 - base, (0.01 * self.steps) % 0.2], dtype=np.float32)


    def make(scale=0.2):
        return Drifting(scale=scale)
    """
)


def _episode(agent, data: Path) -> np.ndarray:
    """The executed levers of one seeded episode of ``agent``, one row per step."""
    env = SolarChainEnv(config=CONFIG, table=load_table(data), action_mode=agent.action_mode)
    (result,) = run_policy(env, agent, setting="main", run_seeds=[SEED], episodes=1)
    return np.column_stack([np.asarray(result.steps[c]) for c in LEVERS])


def _three_ways(reference, item: str, data: Path, *, varies: bool = True, **options) -> list:
    """``reference`` and the agents ``item`` builds through a request and through the runner, each
    driven through the same episode; returns the three agents after asserting they act alike
    (``varies``: the reference's actions change within the episode, so they tell agents apart)."""
    with ExitStack() as stack:
        by_request = build_agents(agent_requests([item], **options), AgentContext(CONFIG), stack=stack)[0]
        spec = EvaluationSpec(policies=[item], config=CONFIG, **options)
        by_runner = make_policies(spec, stack)[0]
        agents = [reference, by_request, by_runner]
        assert len({(a.name, a.action_mode, access_label(a)) for a in agents}) == 1, agents
        expected = _episode(reference, data)
        assert np.ptp(expected, axis=0).any() == varies
        for agent in agents[1:]:
            np.testing.assert_array_equal(_episode(agent, data), expected)
    return agents


@pytest.fixture
def agent_dir(tmp_path: Path, monkeypatch) -> Path:
    folder = tmp_path / "agents"
    folder.mkdir()
    (folder / "drift_agents.py").write_text(AGENT_MODULE)
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.delitem(sys.modules, "drift_agents", raising=False)
    return folder


@pytest.mark.parametrize("name", ["static", "random", "myopic"])
def test_a_baseline_comes_from_the_task_and_acts_as_the_markets_own(tiny_dataset: Path, name: str) -> None:
    agents = _three_ways(make_baseline(name, CONFIG.market), name, tiny_dataset, varies=name != "static")
    assert all(type(a) is type(agents[0]) for a in agents)  # no shell around the benchmark's own policy


def test_a_renamed_baseline_is_the_builtin_behind_a_shell(tiny_dataset: Path) -> None:
    reference = as_agent(make_baseline("myopic", CONFIG.market), name="mine", builtin=True)
    agents = _three_ways(reference, "mine=myopic", tiny_dataset)
    assert all(a.builtin for a in agents)


def test_a_registered_policy_gets_the_config_and_the_requests_models(tiny_dataset: Path, monkeypatch) -> None:
    seen = []

    def factory(config, models):
        seen.append(dict(models))
        policy = make_baseline("myopic", config.market)
        policy.name = "mine-learned"  # a learned policy is named as registered
        return policy

    monkeypatch.setitem(EXTRA_POLICIES, "mine-learned", factory)
    models = {"mine-learned": tiny_dataset / "model.zip"}
    _three_ways(make_policy("mine-learned", CONFIG, models), "mine-learned", tiny_dataset, models=models)
    assert seen == [models, models, models]


def test_module_and_file_specs_take_their_own_agent_args(tiny_dataset: Path, agent_dir: Path) -> None:
    import drift_agents

    args = {None: {"scale": 0.3}, "f": {"scale": 0.7}}
    _three_ways(as_agent(drift_agents.Drifting(scale=0.3)), "drift_agents:Drifting", tiny_dataset, agent_args=args)
    reference = as_agent(drift_agents.make(scale=0.7), name="f")
    _three_ways(reference, f"f={agent_dir / 'drift_agents.py'}:make", tiny_dataset, agent_args=args)
    request = agent_request(f"f={agent_dir / 'drift_agents.py'}:make", agent_args=args)
    assert request.args == {"scale": 0.7} and request.spec is not None and request.spec.kind == "file"


def test_a_plugin_is_built_like_its_entry_point(tiny_dataset: Path, agent_dir: Path, tmp_path: Path, monkeypatch):
    dist = tmp_path / "site" / "drift_plugin-1.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: drift-plugin\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[solarchain_eval.agents]\ndrift-plugin = drift_agents:make\n")
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    import drift_agents

    _three_ways(as_agent(drift_agents.make(), name="drift-plugin"), "drift-plugin", tiny_dataset)


def test_an_sb3_spec_loads_the_model_and_its_statistics_by_name(tiny_dataset: Path, tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    env = SolarChainEnv(config=CONFIG, table=load_table(tiny_dataset))
    PPO("MlpPolicy", env, seed=0, n_steps=64, batch_size=32, device="cpu").save(tmp_path / "ppo.zip")
    reference = as_agent(SB3ModelAgent(PPO.load(tmp_path / "ppo.zip", device="cpu"), name="p"))
    _three_ways(reference, f"p=sb3:PPO:{tmp_path / 'ppo.zip'}", tiny_dataset)
    request = agent_request(f"p=sb3:PPO:{tmp_path / 'ppo.zip'}", vecnormalize={"p": tmp_path / "p.pkl"})
    assert request.vecnormalize == tmp_path / "p.pkl"
    assert agent_request(f"q=sb3:PPO:{tmp_path / 'ppo.zip'}", vecnormalize={"p": tmp_path}).vecnormalize is None


def test_an_http_agent_is_the_client_the_spec_names(tiny_dataset: Path) -> None:
    server = ScriptedAgentServer(action=[0.3, 0.6, 0.05])
    try:
        with HttpAgent("remote", server.url("/ok")) as client:
            agents = _three_ways(
                as_agent(client, name="remote"), f"remote={server.url('/ok')}", tiny_dataset, varies=False
            )
    finally:
        server.server.shutdown()
    assert {type(a.inner).__name__ for a in agents} == {"HttpAgent"}


def test_the_llm_agent_is_registered_like_the_rest_and_needs_its_endpoint(tiny_dataset: Path) -> None:
    def responder(seen):
        return ok(seen.path, {"reward_ratio": 0.12, "liquidity_ratio": 0.7, "burn_rate": 0.03})

    with FakeOpenAI(responder=responder) as server:
        settings = resolve_llm_settings(
            api="chat", model="fake-model", base_url=server.base_url, environ={"SOLARCHAIN_LLM_API_KEY": "none"}
        )
        with open_llm_agent(LLMOptions(settings), CONFIG.market, name="judge") as reference:
            agents = _three_ways(reference, "judge=llm-agent", tiny_dataset, varies=False, llm=LLMOptions(settings))
    assert {type(a).__name__ for a in agents} == {"LLMAgent"}
    with pytest.raises(AgentSpecError, match=r"^the llm-agent needs a model endpoint") as error:
        build_agents(agent_requests(["llm-agent"]), AgentContext(CONFIG))
    assert error.value.message_for().startswith("the llm-agent needs a model endpoint: --llm-backend local")


def test_an_isolated_request_acts_as_the_in_process_one(tiny_dataset: Path, agent_dir: Path) -> None:
    spec = f"{agent_dir / 'drift_agents.py'}:Drifting"
    with ExitStack() as stack:
        here, there = build_agents(
            [agent_request(spec), agent_request(f"iso={spec}", isolate=True)], AgentContext(CONFIG), stack=stack
        )
        assert access_label(there) == "isolated" and access_label(here) == "in-process"
        np.testing.assert_array_equal(_episode(there, tiny_dataset), _episode(here, tiny_dataset))


def test_an_agent_object_is_wrapped_and_the_benchmarks_own_is_not(tiny_dataset: Path, agent_dir: Path) -> None:
    import drift_agents

    static = make_baseline("static", CONFIG.market)
    user = drift_agents.Drifting()
    names: list[tuple[str, str | None]] = []
    built = build_agents(
        agent_requests([static, user, "myopic"]),
        AgentContext(CONFIG),
        check_name=lambda name, builtin: names.append((name, builtin)),
    )
    assert built[0] is static and built[1].inner is user and built[1].name == "Drifting"
    assert names == [("Drifting", None), ("myopic", "myopic")]  # the benchmark's own object is not checked


def test_an_unknown_spec_is_one_line_naming_it() -> None:
    with pytest.raises(AgentSpecError) as error:
        agent_requests(["static", "no-such-agent"])
    message = str(error.value)
    assert message.startswith("unknown policy 'no-such-agent': choose from static, random, myopic, ppo")
    assert "\n" not in message


def test_two_agents_with_one_name_and_a_request_of_nothing_are_refused() -> None:
    with pytest.raises(AgentSpecError, match="agent name 'static' is used twice"):
        build_agents(agent_requests(["static", "static"]), AgentContext(CONFIG))
    with pytest.raises(ValueError, match="either a spec or an agent object"):
        AgentRequest()


def test_the_built_in_names_are_the_requested_tasks_baselines() -> None:
    from solarchain_eval.tasks.registry import register_task, unregister_task
    from toy_task import TOY_TASK, SteadyPolicy

    register_task(TOY_TASK)
    try:
        (steady,) = build_agents(agent_requests(["steady"], task="toy-stock"), AgentContext(None, task="toy-stock"))
        assert isinstance(steady, SteadyPolicy)
        with pytest.raises(AgentSpecError, match="^unknown policy 'static': choose from steady, ppo"):
            agent_requests(["static"], task="toy-stock")  # the solar market's baselines are not the toy's
    finally:
        unregister_task("toy-stock")
