"""Secrets and time limits of the LLM layer against the local scripted server: a key echoed by
the server is never stored or printed, ``--llm-timeout`` bounds each attempt's total time, and
cache entries and logs are strict JSON."""

from __future__ import annotations

import json
import math
import sys
import time

import pytest
from typer.testing import CliRunner

from fake_openai import (
    VALID_AUDIT,
    VALID_PLAN,
    FakeOpenAI,
    Reply,
    chat_body,
    default_responder,
    ok,
    schema_name,
)
from solarchain_eval.cli import app
from solarchain_eval.governance.schemas import AuditorOutput, PlannerOutput
from solarchain_eval.llm import CallSite, LLMSchemaError, LLMTransportError, StructuredLLM, resolve_llm_settings

KEY = "sk-echo-SECRET-5a4b3c2d1e0f"
SITE = CallSite("auditor", "ppo", 20260511, 4, 7)
PLANNER_SITE = CallSite("planner", "ppo", 20260511, 4, None)
MESSAGES = [{"role": "system", "content": "s"}, {"role": "user", "content": 'Context (JSON):\n{"step": 0}'}]


def client(server: FakeOpenAI, *, mode: str = "off", cache=None, **kw) -> StructuredLLM:
    settings = resolve_llm_settings(
        api="chat", model="fake-model", base_url=server.base_url, environ={"SOLARCHAIN_LLM_API_KEY": KEY}, **kw
    )
    return StructuredLLM(settings, cache_dir=cache, cache_mode=mode)


def test_dripping_server_is_cut_off_at_the_timeout():
    body = json.dumps(chat_body(json.dumps(VALID_AUDIT)))
    # 0.5 s per byte: every single read succeeds well within httpx's 1 s read timeout.
    with FakeOpenAI([Reply(200, body, drip_s=0.5)]) as server:
        llm = client(server, timeout_s=1.0, max_retries=0)
        started = time.monotonic()
        with pytest.raises(LLMTransportError, match="no answer within 1 s after 1 attempt"):
            llm.request(MESSAGES, AuditorOutput, SITE)
        elapsed = time.monotonic() - started
    assert elapsed < 2.0, elapsed


def test_each_retry_gets_its_own_deadline_and_a_prompt_answer_is_unaffected():
    body = json.dumps(chat_body(json.dumps(VALID_AUDIT)))
    with FakeOpenAI([Reply(200, body, drip_s=0.5), Reply(200, body, drip_s=0.5)]) as server:
        llm = client(server, timeout_s=0.8, max_retries=1)
        started = time.monotonic()
        with pytest.raises(LLMTransportError, match="after 2 attempt"):
            llm.request(MESSAGES, AuditorOutput, SITE)
        elapsed = time.monotonic() - started
        assert len(server.seen) == 2 and elapsed < 0.8 * 2 + 2.0, elapsed  # SDK back-off is under 1 s
        reply = llm.request(MESSAGES, AuditorOutput, SITE)  # the script is spent: a prompt answer
    assert reply.output.decision in ("revise", "approve")


def test_key_echoed_in_a_valid_reply_is_not_cached_or_returned(tmp_path):
    plan = dict(VALID_PLAN, rationale=f"You sent {KEY}; prefix {KEY[:12]}")
    reply = Reply(200, chat_body(json.dumps(plan)), {"x-request-id": f"req-{KEY}"})
    with FakeOpenAI([reply]) as server:
        llm = client(server, mode="record", cache=tmp_path / "cache")
        answer = llm.request(MESSAGES, PlannerOutput, PLANNER_SITE)
    (entry,) = (tmp_path / "cache").rglob("*.json")
    text = entry.read_text(encoding="utf-8")
    assert "SECRET" not in text and "[redacted]" in text
    assert "SECRET" not in answer.output.rationale and "[redacted]" in answer.output.rationale
    assert "SECRET" not in json.dumps(answer.meta)


def test_key_echoed_in_an_invalid_reply_is_not_in_the_snippet():
    bad = {"decision": "maybe", "reason": f"echo {KEY}"}
    with FakeOpenAI([ok("/v1/chat/completions", bad)]) as server, pytest.raises(LLMSchemaError) as caught:
        client(server).request(MESSAGES, AuditorOutput, SITE)
    message = str(caught.value)
    assert "output began" in message and "[redacted]" in message and "SECRET" not in message


def test_nan_in_the_envelope_is_stored_as_null_and_entries_are_strict_json(tmp_path):
    body = chat_body(json.dumps(VALID_AUDIT))
    body["system_fingerprint"] = math.nan
    body["choices"][0]["logprobs"] = {"score": math.inf}
    with FakeOpenAI([Reply(200, json.dumps(body))]) as server:  # json.dumps writes NaN / Infinity
        llm = client(server, mode="record", cache=tmp_path / "cache")
        llm.request(MESSAGES, AuditorOutput, SITE)
    (entry,) = (tmp_path / "cache").rglob("*.json")
    stored = json.loads(entry.read_text(encoding="utf-8"), parse_constant=lambda c: pytest.fail(f"{c} in the cache"))
    assert stored["response"]["system_fingerprint"] is None
    assert stored["response"]["choices"][0]["logprobs"] == {"score": None}


def test_a_non_strict_cache_entry_is_refused(tmp_path):
    with FakeOpenAI([ok("/v1/chat/completions", VALID_AUDIT)]) as server:
        llm = client(server, mode="record", cache=tmp_path / "cache")
        llm.request(MESSAGES, AuditorOutput, SITE)
    (entry,) = (tmp_path / "cache").rglob("*.json")
    entry.write_text(entry.read_text().replace('"latency_s": ', '"latency_s": NaN, "x": '), encoding="utf-8")
    from solarchain_eval.llm import LLMError

    settings = resolve_llm_settings(api="chat", model="fake-model", environ={})
    with pytest.raises(LLMError, match="not valid JSON"):
        StructuredLLM(settings, cache_dir=tmp_path / "cache", cache_mode="replay").request(
            MESSAGES, AuditorOutput, SITE
        )


def test_cli_run_with_an_echoing_server_stores_and_prints_no_key(tiny_dataset, tmp_path, monkeypatch):
    for name in (
        "SOLARCHAIN_LLM_BASE_URL",
        "SOLARCHAIN_LLM_MODEL",
        "OPENAI_API_KEY",
        "OPENAI_BASE_URL",
        "OPENAI_MODEL",
    ):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("SOLARCHAIN_LLM_API_KEY", KEY)

    def echo(seen):
        if schema_name(seen.path, seen.body) == "PlannerOutput":
            return ok(seen.path, dict(VALID_PLAN, rationale=f"key {KEY}"))
        reply = default_responder(seen)
        audit = json.loads(reply.body["choices"][0]["message"]["content"])
        return ok(seen.path, dict(audit, reason=f"{audit['reason']} {KEY}"))

    out, cache = tmp_path / "run", tmp_path / "cache"
    with FakeOpenAI(responder=echo) as server:
        url = server.base_url.replace("http://", "http://alice:pw-SECRET@")
        args = [
            "evaluate",
            "--data",
            str(tiny_dataset),
            "--policies",
            "myopic",
            "--seeds",
            "5",
            "--episodes",
            "1",
            "--out",
            str(out),
            "--agentic",
            "planner_auditor",
            "--planner",
            "llm",
            "--auditor",
            "llm",
            "--llm-api",
            "chat",
            "--llm-model",
            "fake-model",
            "--llm-base-url",
            url,
            "--llm-cache",
            str(cache),
            "--llm-cache-mode",
            "record",
        ]
        monkeypatch.setattr(sys, "argv", ["solarchain-eval", *args])  # what the CLI records
        result = CliRunner().invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert "SECRET" not in result.output
    written = [*out.iterdir(), *cache.rglob("*.json")]
    assert any("[redacted]" in p.read_text(encoding="utf-8") for p in written if p.name == "agentic_logs.jsonl")
    for path in written:
        assert "SECRET" not in path.read_text(encoding="utf-8"), path
    meta = json.loads((out / "run_metadata.json").read_text())
    assert "http://[redacted]@127.0.0.1:" in " ".join(meta["command"])


def test_a_server_echoing_the_url_token_in_an_error_gets_it_redacted():
    with FakeOpenAI() as server:  # its 404 message repeats the path, query included
        settings = resolve_llm_settings(
            api="chat",
            model="m",
            base_url=server.base_url + "?token=tok-SECRET-77",
            environ={"SOLARCHAIN_LLM_API_KEY": KEY},
            max_retries=0,
        )
        with pytest.raises(LLMTransportError) as caught:
            StructuredLLM(settings).request(MESSAGES, AuditorOutput, SITE)
    assert "HTTP 404" in str(caught.value) and "SECRET" not in str(caught.value)
