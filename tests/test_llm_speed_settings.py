"""The settings that make local Planner/Auditor calls cheaper (docs/llm.md#speed); no model needed.

The differential test against the server's default settings runs the real model
(tests/test_llm_local_model.py).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from solarchain_eval.config import MarketConfig
from solarchain_eval.governance.prompts import auditor_messages, planner_messages
from solarchain_eval.llm.serving import local_server
from solarchain_eval.market.actions import ActionCodec
from solarchain_eval.perf.llm_bench import episode_situation, step_situation


def _flag(command: list[str], name: str) -> str:
    return command[command.index(name) + 1]


def test_server_reads_only_the_last_logits_and_drafts_nothing():
    spec = local_server.ServerSpec(model_path=Path("m.gguf"), model_name="m", port=1234, threads=1)
    command = local_server.LocalServer(spec).command()
    assert _flag(command, "--logits_all") == "False"
    assert "--flash_attn" not in command  # measured slower here
    assert "--draft_model" not in command  # prompt-lookup decoding changed replies and cost more CPU
    assert _flag(command, "--n_threads") == _flag(command, "--n_threads_batch") == "1"


def _shared_prefix(a: str, b: str) -> int:
    n = 0
    while n < min(len(a), len(b)) and a[n] == b[n]:
        n += 1
    return n


def test_every_call_shares_the_system_prompt_and_audits_share_the_episode_part():
    codec = ActionCodec.from_config(MarketConfig())
    plan = planner_messages(episode_situation("risky", 2).to_prompt(codec))
    audits = [
        auditor_messages(step_situation(risk, codec, step, 2).to_prompt(codec))
        for risk, step in (("calm", 3), ("risky", 4))
    ]
    # a prefix-caching server re-reads only the user message when the role changes ...
    assert plan[0] == audits[0][0] == audits[1][0] and plan[0]["role"] == "system"
    assert "Planner" in plan[1]["content"].split("\n")[0] and "Auditor" in audits[0][1]["content"].split("\n")[0]
    # ... and, between two audits of an episode, only what follows the plan
    user = [a[1]["content"] for a in audits]
    assert _shared_prefix(*user) >= user[0].index('"step":') > user[0].index('"planner_policy":')


def _request(**values):
    from solarchain_eval.governance.request import GovernanceRequest

    return GovernanceRequest(agentic="planner_auditor", planner="llm", auditor="llm", **values)


def test_model_threads_default_to_the_available_cpus_at_most_two(monkeypatch):
    monkeypatch.setattr(local_server.os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    assert local_server.default_threads() == 2
    assert local_server.ServerSpec(model_path=Path("m.gguf"), model_name="m").threads == 2
    monkeypatch.setattr(local_server.os, "sched_getaffinity", lambda pid: {5})
    assert local_server.default_threads() == 1


def test_llm_threads_reach_the_server_and_are_checked(monkeypatch):
    from solarchain_eval.governance.request import GovernanceRequestError

    monkeypatch.setattr(local_server, "resolve_model", lambda model: ("m", Path("m.gguf")))
    request = _request(llm_backend="local", llm_threads=3)
    spec = request.server_spec(request.resolve())
    assert spec.threads == 3 and _flag(local_server.LocalServer(spec).command(), "--n_threads_batch") == "3"
    default = _request(llm_backend="local")
    assert default.server_spec(default.resolve()).threads == local_server.default_threads()
    for bad, message in (({"llm_backend": "local", "llm_threads": 0}, ">= 1"), ({"llm_threads": 2}, "local")):
        with pytest.raises(GovernanceRequestError) as caught:
            _request(llm_api="chat", llm_model="x", **bad).resolve()
        assert message in caught.value.message_for() and "--llm-threads" in caught.value.message_for()


def test_llm_decoding_reaches_the_server_and_the_cache_key(monkeypatch):
    from solarchain_eval.governance.request import GovernanceRequestError
    from solarchain_eval.governance.schemas import AuditorOutput
    from solarchain_eval.llm.cache import request_key
    from solarchain_eval.llm.client import StructuredLLM

    monkeypatch.setattr(local_server, "resolve_model", lambda model: ("m", Path("m.gguf")))
    keys = {}
    for decoding in (None, "jump-forward", "grammar"):
        request = _request(llm_backend="local", llm_decoding=decoding)
        options = request.resolve()
        spec = request.server_spec(options)
        chat_format = _flag(local_server.LocalServer(spec).command(), "--chat_format")
        assert chat_format == local_server.DECODINGS[decoding or "jump-forward"]
        assert options.llm.describe()["decoding"] == (decoding or "jump-forward")
        client = StructuredLLM(options.llm.settings)
        keys[decoding] = request_key(client.canonical_request([{"role": "user", "content": "x"}], AuditorOutput))
        client.close()
    # the two decodings answer differently: a recording of one never replays for the other
    assert keys[None] == keys["jump-forward"] != keys["grammar"]
    for bad, message in (
        ({"llm_backend": "local", "llm_decoding": "beam"}, "jump-forward, grammar"),
        ({"llm_decoding": "grammar"}, "local"),
    ):
        with pytest.raises(GovernanceRequestError) as caught:
            _request(llm_api="chat", llm_model="x", **bad).resolve()
        assert message in caught.value.message_for() and "--llm-decoding" in caught.value.message_for()
