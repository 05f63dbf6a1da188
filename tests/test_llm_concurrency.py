"""``evaluate --llm-concurrency N``: episodes in flight give the files of the sequential run."""

from __future__ import annotations

import hashlib
import json
import threading
import time

import pytest
from typer.testing import CliRunner

from fake_openai import FakeOpenAI, Reply, chat_body, default_responder, schema_name, user_context
from solarchain_eval.cli import app
from solarchain_eval.evaluation.inflight import plan_tasks
from solarchain_eval.evaluation.rollout import paper_episode_seeds
from solarchain_eval.market.baselines import MyopicPolicy, RandomPolicy, StaticPolicy

COMPARED = ("metrics.csv", "actions.csv", "city_hour_policy.csv", "agentic_logs.jsonl", "summary.json")


@pytest.fixture
def clean_env(monkeypatch):
    for name in ("SOLARCHAIN_LLM_API_KEY", "SOLARCHAIN_LLM_BASE_URL", "SOLARCHAIN_LLM_MODEL", "OPENAI_API_KEY"):
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def args(data, out, *extra):
    return [
        "evaluate",
        "--data",
        str(data),
        "--policies",
        "random,myopic,static",
        "--seeds",
        "5,9",
        "--episodes",
        "2",
        "--out",
        str(out),
        "--agentic",
        "planner_auditor",
        *extra,
    ]


class Tracker:
    """A responder with request-dependent delays (so answers finish out of order) that counts
    the requests in flight."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.in_flight = 0
        self.most_in_flight = 0

    def __call__(self, seen) -> Reply:
        with self.lock:
            self.in_flight += 1
            self.most_in_flight = max(self.most_in_flight, self.in_flight)
        try:
            digest = hashlib.sha256(repr(sorted(user_context(seen.path, seen.body).items())).encode()).digest()
            time.sleep(digest[0] / 255 * 0.03)
            return default_responder(seen)
        finally:
            with self.lock:
                self.in_flight -= 1


def test_tasks_split_stateless_policies_by_episode_and_others_by_run():
    policies = [RandomPolicy(), MyopicPolicy(), StaticPolicy()]
    tasks = plan_tasks(policies, [5, 9], 3, paper_episode_seeds)
    random_tasks = [t for t in tasks if t.policy_index == 0]
    assert [(t.run_seed, t.episodes) for t in random_tasks] == [
        (5, ((0, 5), (1, 6), (2, 7))),
        (9, ((0, 9), (1, 10), (2, 11))),
    ]
    myopic = [t for t in tasks if t.policy_index == 1]
    assert [(t.run_seed, t.episodes) for t in myopic] == [(5, ((e, 5 + e),)) for e in range(3)] + [
        (9, ((e, 9 + e),)) for e in range(3)
    ]
    assert len(tasks) == 2 + 6 + 6


def test_rule_layer_in_flight_equals_sequential(tiny_dataset, tmp_path, clean_env):
    runner = CliRunner()
    one = runner.invoke(app, args(tiny_dataset, tmp_path / "one"), catch_exceptions=False)
    four = runner.invoke(app, args(tiny_dataset, tmp_path / "four", "--llm-concurrency", "4"), catch_exceptions=False)
    assert one.exit_code == 0 and four.exit_code == 0, one.output + four.output
    for name in COMPARED:
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "four" / name).read_bytes(), name


def _without_latency(path) -> list[dict]:
    """Log rows without the measured call latencies (they differ between any two live runs)."""
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    for row in rows:
        for meta in (row["llm"], row["plan"]["llm"]):
            if meta is not None:
                meta.pop("latency_s")
    return rows


def test_llm_layer_in_flight_equals_sequential_and_replays(tiny_dataset, tmp_path, clean_env):
    clean_env.setenv("SOLARCHAIN_LLM_API_KEY", "sk-concurrency-test")
    llm = ["--planner", "llm", "--auditor", "llm", "--llm-api", "chat", "--llm-model", "fake-model"]
    runner = CliRunner()
    tracker = Tracker()

    def run(out, *extra):
        result = runner.invoke(app, args(tiny_dataset, tmp_path / out, *llm, *extra), catch_exceptions=False)
        assert result.exit_code == 0, result.output
        return tmp_path / out

    with FakeOpenAI(responder=tracker) as server:
        one = run("one", "--llm-base-url", server.base_url)
        sequential_most = tracker.most_in_flight
        many = run(
            "many", "--llm-base-url", server.base_url, "--llm-concurrency", "4", "--llm-cache", str(tmp_path / "c")
        )
    assert sequential_most == 1 and tracker.most_in_flight > 1  # episodes really were in flight together
    for name in COMPARED:
        if name != "agentic_logs.jsonl":
            assert (many / name).read_bytes() == (one / name).read_bytes(), name
    assert _without_latency(many / "agentic_logs.jsonl") == _without_latency(one / "agentic_logs.jsonl")
    # the recording replays exactly, in flight or not, without key or server
    clean_env.delenv("SOLARCHAIN_LLM_API_KEY")
    replay = ["--llm-cache", str(tmp_path / "c"), "--llm-cache-mode", "replay"]
    for out, workers in (("replay1", "1"), ("replay3", "3")):
        replayed = run(out, *replay, "--llm-concurrency", workers)
        for name in COMPARED:
            assert (replayed / name).read_bytes() == (many / name).read_bytes(), (out, name)


def test_a_failing_episode_in_flight_fails_the_run_without_output(tiny_dataset, tmp_path, clean_env):
    clean_env.setenv("SOLARCHAIN_LLM_API_KEY", "sk-concurrency-test")

    def refuse_one_audit(seen) -> Reply:
        if schema_name(seen.path, seen.body) == "AuditorOutput" and user_context(seen.path, seen.body)["step"] == 3:
            return Reply(200, chat_body(None, refusal="I will not audit this"))
        return default_responder(seen)

    with FakeOpenAI(responder=refuse_one_audit) as server:
        result = CliRunner().invoke(
            app,
            args(
                tiny_dataset,
                tmp_path / "run",
                "--auditor",
                "llm",
                "--llm-api",
                "chat",
                "--llm-model",
                "fake-model",
                "--llm-base-url",
                server.base_url,
                "--llm-concurrency",
                "3",
                "--llm-max-retries",
                "0",
            ),
        )
    assert result.exit_code == 2, result.output
    assert "refus" in result.output and "step 3" in result.output
    assert not (tmp_path / "run").exists() or not any((tmp_path / "run").iterdir())


def test_concurrency_needs_the_agentic_layer(tiny_dataset, tmp_path):
    result = CliRunner().invoke(
        app,
        [
            "evaluate",
            "--data",
            str(tiny_dataset),
            "--episodes",
            "1",
            "--out",
            str(tmp_path / "r"),
            "--llm-concurrency",
            "2",
        ],
    )
    assert result.exit_code == 2 and "--llm-concurrency needs --agentic planner_auditor" in result.output


class _Started(Exception):
    """Raised by the stand-in server start: the test needs the spec, not a run."""


@pytest.mark.parametrize("concurrency", ["1", "3"])
def test_local_server_takes_one_request_per_episode_in_flight(tiny_dataset, tmp_path, clean_env, concurrency):
    """--llm-concurrency is evaluate's own option (not a GovernanceRequest field), yet the local
    server it starts must get that many parallel slots, else a request interrupts another."""
    from solarchain_eval.cli import agentic as agentic_cli

    gguf = tmp_path / "tiny-model.gguf"
    gguf.write_bytes(b"GGUF")
    started = []

    def serving(spec, log_path=None):
        started.append(spec)
        raise _Started

    clean_env.setattr(agentic_cli.local_server, "serving", serving)
    extra = ["--planner", "llm", "--llm-backend", "local", "--llm-model", str(gguf), "--llm-concurrency", concurrency]
    result = CliRunner().invoke(app, args(tiny_dataset, tmp_path / "run", *extra))
    assert isinstance(result.exception, _Started), result.output
    assert [(s.model_path, s.parallel) for s in started] == [(gguf, int(concurrency))]
