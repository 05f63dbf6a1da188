"""Agents behind HTTP: the example server, the request contract, errors, retries and keep-alive."""

from __future__ import annotations

import copy
import importlib.util
import math
import subprocess
import sys
import threading
from http.server import ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from agent_server import ScriptedAgentServer
from solarchain_eval.agents.http_agent import REQUEST_KEYS, HttpAgent, HttpAgentError
from solarchain_eval.cli import app
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.evaluation.inflight import run_in_flight
from solarchain_eval.evaluation.rollout import run_policy
from solarchain_eval.market.observation import OBSERVATION_NAMES
from solarchain_eval.perf.agent_bench import EXAMPLE_SERVER, ConstantAgent, measure_agent_overhead, static_action
from solarchain_eval.protocol import PAPER_SEED

F32 = np.float32


@pytest.fixture(scope="module")
def example_url():
    """The example server as a user runs it, on a free port; its URL as it prints it."""
    process = subprocess.Popen(
        [sys.executable, str(EXAMPLE_SERVER), "--port", "0"], stdout=subprocess.PIPE, text=True
    )  # fmt: skip
    line = process.stdout.readline()
    assert line.startswith("agent listening on http://127.0.0.1:"), line
    yield line.split()[-1]
    process.terminate()
    process.wait(timeout=10)


@pytest.fixture(scope="module")
def example_rule():
    spec = importlib.util.spec_from_file_location("http_agent_server", EXAMPLE_SERVER)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def scripted():
    server = ScriptedAgentServer(action=[float(v) for v in static_action()])
    yield server
    server.close()


class LocalRule:
    """The example server's rule as a local Python agent."""

    name = "local"
    action_mode = "continuous"

    def __init__(self, decide):
        self.decide = decide

    def begin_run(self, run_seed):
        return None

    def act(self, observation):
        return np.array(self.decide(dict(zip(OBSERVATION_NAMES, observation.tolist(), strict=True))), F32)


class Recording(HttpAgent):
    """Keeps every observation the runner hands to ``act``."""

    def act(self, observation):
        self.observations = [*getattr(self, "observations", []), observation.copy()]
        return super().act(observation)


def one_episode(env, policy, run_seed=PAPER_SEED, episodes=1):
    return list(run_policy(env, policy, setting="physics", run_seeds=(run_seed,), episodes=episodes))


def test_rollout_through_the_example_server_equals_the_same_rule_in_python(tiny_dataset, example_url, example_rule):
    env = SolarChainEnv(tiny_dataset)
    with HttpAgent("mine", example_url) as agent:
        (remote,) = one_episode(env, agent)
    (local,) = one_episode(env, LocalRule(example_rule.decide))
    assert remote.n_steps == 24 and remote.policy == "mine"
    columns = ("reward_ratio", "liquidity_ratio", "burn_rate")
    assert len({tuple(remote.steps[c][i] for c in columns) for i in range(24)}) > 1  # the rule reacts
    assert remote.steps == local.steps  # every per-step column, bit for bit
    assert remote.metrics.keys() == local.metrics.keys()
    for key, value in remote.metrics.items():
        assert value == local.metrics[key] or (math.isnan(value) and math.isnan(local.metrics[key])), key


def test_one_connection_per_episode_and_the_request_is_the_documented_context(tiny_dataset, scripted):
    env = SolarChainEnv(tiny_dataset)
    agent = Recording("mine", scripted.url("/ok"))
    (result,) = one_episode(env, agent, run_seed=PAPER_SEED + 1)
    (static,) = one_episode(env, ConstantAgent(static_action()), run_seed=PAPER_SEED + 1)
    agent.close()
    seen = scripted.seen("/ok")
    assert len(seen) == 24
    assert len({r.client for r in seen}) == 1  # keep-alive: one TCP connection for the episode
    assert result.steps == static.steps  # the server's JSON floats decode to Static's float32 action
    for step, (request, observation) in enumerate(zip(seen, agent.observations, strict=True)):
        body = request.body
        assert list(body) == list(REQUEST_KEYS)
        assert body["observation"] == observation.astype(np.float64).tolist()  # full precision
        assert np.array_equal(np.array(body["observation"], F32), observation)
        assert body["observation_names"] == list(OBSERVATION_NAMES)
        hour = result.start_hour + step
        assert (body["hour"], body["hour_of_day"], body["step"]) == (hour, hour % 24, step)
        assert (body["episode"], body["episode_seed"], body["run_seed"]) == (0, PAPER_SEED + 1, PAPER_SEED + 1)
        assert body["observation"][0] == F32(np.sin(2 * np.pi * (hour % 24) / 24))  # hour_sin of that hour


def test_the_example_server_keeps_one_connection_for_an_episode(tiny_dataset, example_rule):
    clients = []

    class Counting(example_rule.AgentHandler):
        def do_POST(self):
            clients.append(self.client_address)
            super().do_POST()

    server = ThreadingHTTPServer(("127.0.0.1", 0), Counting)
    threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True).start()
    try:
        with HttpAgent("mine", f"http://127.0.0.1:{server.server_address[1]}/act") as agent:
            one_episode(SolarChainEnv(tiny_dataset), agent)
    finally:
        server.shutdown()
        server.server_close()
    assert len(clients) == 24 and len(set(clients)) == 1


def test_closing_and_reusing_opens_a_new_connection(scripted):
    agent = HttpAgent("mine", scripted.url("/ok"))
    agent.begin_episode(episode=0, run_seed=1, episode_seed=1, start_hour=0)
    agent.act(np.zeros(12, F32))
    agent.close()
    agent.act(np.zeros(12, F32))
    clients = [r.client for r in scripted.seen("/ok")]
    assert len(clients) == 2 and clients[0] != clients[1]
    agent.close()


def fail(agent: HttpAgent) -> str:
    agent.begin_episode(episode=3, run_seed=PAPER_SEED, episode_seed=PAPER_SEED + 3, start_hour=48)
    with pytest.raises(HttpAgentError) as caught:
        agent.act(np.zeros(12, F32))
    return str(caught.value)


@pytest.mark.parametrize(
    ("path", "problem"),
    [
        ("/range", "reply action[1]=1.7 is outside [0, 1]"),
        ("/length", "reply action must be a list of 3 numbers, got [0.1, 0.2]"),
        ("/notjson", "reply is not JSON: '<html>oops</html>'"),
        ("/nan", "reply action[1]=NaN is not finite"),
        ("/noaction", """reply has no "action" key: '{"act": 1}'"""),
        ("/missing", "reply HTTP 404 Not Found: 'no such agent'"),
    ],
)
def test_a_bad_reply_fails_at_once_in_one_line_naming_agent_url_and_position(scripted, path, problem):
    url = scripted.url(path)
    message = fail(HttpAgent("mine", url, retries=2))
    assert message == f"agent 'mine' ({url}): {problem} (run seed {PAPER_SEED}, episode 3, step 0)"
    assert len(scripted.seen(path)) == 1  # not retried


def test_a_5xx_is_retried_and_the_step_goes_on(scripted):
    agent = HttpAgent("mine", scripted.url("/flaky"), retries=1)
    agent.begin_episode(episode=0, run_seed=5, episode_seed=5, start_hour=0)
    assert np.array_equal(agent.act(np.zeros(12, F32)), static_action())
    assert len(scripted.seen("/flaky")) == 2
    seen = scripted.seen("/flaky")
    assert seen[0].body == seen[1].body  # the retry repeats the request
    agent.act(np.zeros(12, F32))
    assert scripted.seen("/flaky")[-1].body["step"] == 1


def test_a_server_that_keeps_failing_is_reported_after_the_retries(scripted):
    url = scripted.url("/down")
    message = fail(HttpAgent("mine", url, retries=2))
    problem = "HTTP 500 Internal Server Error: 'internal error with a second line' (3 attempts)"
    assert message == f"agent 'mine' ({url}): {problem} (run seed {PAPER_SEED}, episode 3, step 0)"
    assert len(scripted.seen("/down")) == 3


def test_a_timeout_is_retried_then_reported(scripted):
    url = scripted.url("/slow")
    message = fail(HttpAgent("mine", url, timeout_s=0.2, retries=1))
    assert (
        message
        == f"agent 'mine' ({url}): no reply within timeout_s=0.2 (2 attempts) (run seed {PAPER_SEED}, episode 3, step 0)"
    )
    assert len(scripted.seen("/slow")) == 2


@pytest.mark.parametrize(("reply", "expected"), [("7", 7), ("[124]", 124), ("0", 0)])
def test_discrete_replies(scripted, reply, expected):
    agent = HttpAgent("d", scripted.url(f"/discrete/{reply}"), action_mode="discrete")
    agent.begin_episode(episode=0, run_seed=1, episode_seed=1, start_hour=0)
    assert agent.act(np.zeros(12, F32)) == expected


@pytest.mark.parametrize(
    ("reply", "problem"),
    [
        ("125", "reply action=125 is outside 0..124"),
        ("-1", "reply action=-1 is outside 0..124"),
        ("3.0", "reply action must be an integer index or [index], got 3.0"),
        ("true", "reply action must be an integer index or [index], got true"),
        ("[1,2]", "reply action must be an integer index or [index], got [1, 2]"),
    ],
)
def test_bad_discrete_replies(scripted, reply, problem):
    message = fail(HttpAgent("d", scripted.url(f"/discrete/{reply}"), action_mode="discrete"))
    assert f": {problem} (run seed" in message


def test_construction_checks_the_url_and_that_something_listens(scripted):
    with pytest.raises(
        HttpAgentError, match=r"^agent 'mine' \(ftp://x/act\): the URL must start with http:// or https://$"
    ):
        HttpAgent("mine", "ftp://x/act")
    with pytest.raises(HttpAgentError, match="names no host"):
        HttpAgent("mine", "http:///act")
    with pytest.raises(HttpAgentError, match="port is not a number"):
        HttpAgent("mine", "http://127.0.0.1:99999/act")
    with pytest.raises(HttpAgentError, match="action_mode must be one of continuous, discrete"):
        HttpAgent("mine", scripted.url("/ok"), action_mode="box")
    free_port = scripted.server.server_address[1]
    scripted.close()  # nothing listens there any more
    url = f"http://127.0.0.1:{free_port}/act"
    with pytest.raises(HttpAgentError) as caught:
        HttpAgent("mine", url)
    assert str(caught.value).startswith(f"agent 'mine' ({url}): cannot connect to 127.0.0.1:{free_port} (")
    assert "\n" not in str(caught.value)


def test_credentials_in_the_url_never_appear_in_errors(scripted):
    port = scripted.server.server_address[1]
    message = fail(HttpAgent("mine", f"http://user:hunter2@127.0.0.1:{port}/range?token=abc"))
    assert "hunter2" not in message and "abc" not in message
    assert f"(http://[redacted]@127.0.0.1:{port}/range?token=[redacted])" in message


def test_act_before_begin_episode_is_refused(scripted):
    with pytest.raises(RuntimeError, match="before begin_episode"):
        HttpAgent("mine", scripted.url("/ok")).act(np.zeros(12, F32))


@pytest.mark.parametrize("stateless", [True, False])
def test_episodes_in_flight_match_the_sequential_run(tiny_dataset, scripted, stateless):
    """Stateless: one agent on two threads (context per thread); otherwise private copies per run seed."""
    agent = HttpAgent("mine", scripted.url("/ok"), stateless=stateless)
    seeds = (PAPER_SEED, PAPER_SEED + 1)
    results = run_in_flight(
        [agent], lambda mode: SolarChainEnv(tiny_dataset, action_mode=mode), setting="physics",
        run_seeds=seeds, episodes=2, episode_seeds=lambda s, n: [s + e for e in range(n)], workers=2,
    )  # fmt: skip
    env = SolarChainEnv(tiny_dataset)
    sequential = list(run_policy(env, ConstantAgent(static_action()), setting="physics", run_seeds=seeds, episodes=2))
    assert [r.steps for r in results] == [r.steps for r in sequential]
    by_episode: dict[tuple[int, int], list[int]] = {}
    for request in scripted.seen("/ok"):
        by_episode.setdefault((request.body["run_seed"], request.body["episode"]), []).append(request.body["step"])
    assert sorted(by_episode) == [(s, e) for s in seeds for e in range(2)]
    assert all(steps == list(range(24)) for steps in by_episode.values())
    agent.close()  # closes the copies' connections too
    assert agent._connections.clients == []


def test_a_copy_has_its_own_connection_and_closing_the_original_closes_it(scripted):
    agent = HttpAgent("mine", scripted.url("/ok"))
    twin = copy.deepcopy(agent)
    for policy in (agent, twin):
        policy.begin_episode(episode=0, run_seed=1, episode_seed=1, start_hour=0)
        policy.act(np.zeros(12, F32))
    assert len({r.client for r in scripted.seen("/ok")}) == 2
    clients = list(agent._connections.clients)
    agent.close()
    assert len(clients) == 2 and all(c.is_closed for c in clients)


def test_bench_agent_measures_the_example_server(tiny_dataset):
    result = measure_agent_overhead(tiny_dataset, seeds=1, episodes=1, repeats=1)
    assert result.steps == 24
    assert all(len(s) == 1 and s[0] > 0 for s in (result.static_s, result.python_s, result.http_s))
    assert result.http_overhead_ms_per_step == pytest.approx(1000 * (result.http_s[0] - result.python_s[0]) / 24)
    assert result.python_over_static == pytest.approx(result.python_s[0] / result.static_s[0])
    cpu_ms = 1000 * (result.http_cpu_s[0] - result.python_cpu_s[0]) / 24
    assert result.http_client_cpu_ms_per_step == pytest.approx(cpu_ms)
    output = CliRunner().invoke(
        app, ["bench-agent", "--data", str(tiny_dataset), "--seeds", "1", "--episodes", "1", "--repeats", "1"],
        terminal_width=200,
    )  # fmt: skip
    assert output.exit_code == 0, output.output
    assert "HTTP overhead per step" in output.output and "ratio Python agent / Static" in output.output
    refused = CliRunner().invoke(app, ["bench-agent", "--data", str(tiny_dataset), "--url", "http://127.0.0.1:1/act"])
    assert refused.exit_code == 2 and "cannot connect to 127.0.0.1:1" in refused.output


def test_the_example_server_stays_short_and_standard_library_only():
    source = Path(EXAMPLE_SERVER).read_text()
    imports = {line.split()[1].split(".")[0] for line in source.splitlines() if line.startswith(("import ", "from "))}
    assert imports <= set(sys.stdlib_module_names)
    assert len(source.splitlines()) <= 70
