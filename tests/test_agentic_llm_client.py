"""The LLM client against a local OpenAI-compatible server (127.0.0.1 only)."""

from __future__ import annotations

import json
import math

import pytest

from fake_openai import VALID_AUDIT, VALID_PLAN, FakeOpenAI, Reply, chat_body, ok, responses_body
from solarchain_eval.config import MarketConfig
from solarchain_eval.governance.auditor import LLMAuditor
from solarchain_eval.governance.planner import EpisodeContext, LLMPlanner
from solarchain_eval.governance.schemas import AuditorOutput, PlannerOutput
from solarchain_eval.llm import (
    CallSite,
    LLMCacheMissError,
    LLMConfigError,
    LLMRefusalError,
    LLMSchemaError,
    LLMTransportError,
    LLMTruncatedError,
    StructuredLLM,
    resolve_llm_settings,
)
from solarchain_eval.llm.response_format import response_format
from solarchain_eval.market.actions import ActionCodec

KEY = "sk-test-SECRET-0123456789abcdef"
SITE = CallSite("auditor", "ppo", 20260511, 4, 7)
PLANNER_SITE = CallSite("planner", "ppo", 20260511, 4, None)
MESSAGES = [{"role": "system", "content": "s"}, {"role": "user", "content": 'Context (JSON):\n{"step": 0}'}]
CODEC = ActionCodec.from_config(MarketConfig())
APIS = ("chat", "responses")


def client(server: FakeOpenAI, api: str, *, mode: str = "off", cache=None, **kw) -> StructuredLLM:
    settings = resolve_llm_settings(
        api=api, model="fake-model", base_url=server.base_url, environ={"SOLARCHAIN_LLM_API_KEY": KEY}, **kw
    )
    return StructuredLLM(settings, cache_dir=cache, cache_mode=mode)


def path(api: str) -> str:
    return "/v1/chat/completions" if api == "chat" else "/v1/responses"


@pytest.mark.parametrize("api", APIS)
def test_valid_output_and_the_request_sent(api):
    with FakeOpenAI([ok(path(api), VALID_PLAN)]) as server:
        llm = client(server, api, max_output_tokens=777)
        reply = llm.request(MESSAGES, PlannerOutput, PLANNER_SITE)
        llm.close()
    assert reply.output == PlannerOutput.model_validate(VALID_PLAN)
    assert reply.meta["kind"] == "planner" and reply.meta["model"] == "fake-model"
    assert reply.meta["request_id"] == "req-test-1" and reply.meta["retries"] == 0
    assert reply.meta["input_tokens"] == (120 if api == "chat" else 130)
    assert len(reply.meta["cache_key"]) == 64
    (seen,) = server.seen
    assert seen.path == path(api)
    assert seen.headers["authorization"] == f"Bearer {KEY}"
    assert "temperature" not in seen.body  # omitted unless given
    schema = response_format(PlannerOutput, api)
    if api == "chat":
        assert seen.body["response_format"] == schema and seen.body["max_completion_tokens"] == 777
        assert seen.body["messages"] == MESSAGES
    else:
        assert seen.body["text"] == {"format": schema} and seen.body["max_output_tokens"] == 777
        assert seen.body["input"] == MESSAGES
    # The SDK's strict schema: every object closed, every property required.
    strict = schema["json_schema"]["schema"] if api == "chat" else schema["schema"]
    assert strict["additionalProperties"] is False and set(strict["required"]) == set(VALID_PLAN)
    assert strict["$defs"]["AuditPolicy"]["additionalProperties"] is False


@pytest.mark.parametrize("api", APIS)
def test_temperature_is_sent_when_given(api):
    with FakeOpenAI([ok(path(api), VALID_AUDIT)]) as server:
        client(server, api, temperature=0.0).request(MESSAGES, AuditorOutput, SITE)
    assert server.seen[0].body["temperature"] == 0.0


@pytest.mark.parametrize(
    ("api", "reply", "error", "text"),
    [
        ("chat", Reply(200, chat_body(None, refusal="I cannot help with that.")), LLMRefusalError, "I cannot help"),
        (
            "responses",
            Reply(200, responses_body(None, refusal="I cannot help with that.")),
            LLMRefusalError,
            "I cannot help",
        ),
        ("chat", Reply(200, chat_body('{"decision": "appr', finish_reason="length")), LLMTruncatedError, "length"),
        (
            "responses",
            Reply(200, responses_body('{"deci', status="incomplete", incomplete_reason="max_output_tokens")),
            LLMTruncatedError,
            "max_output_tokens",
        ),
        (
            "chat",
            Reply(200, chat_body(json.dumps({**VALID_AUDIT, "confidence": 0.9}))),
            LLMSchemaError,
            "confidence: Extra inputs are not permitted",
        ),
        (
            "responses",
            Reply(200, responses_body(json.dumps({k: v for k, v in VALID_AUDIT.items() if k != "reason"}))),
            LLMSchemaError,
            "reason: Field required",
        ),
        (
            "chat",
            Reply(200, chat_body(json.dumps(VALID_AUDIT).replace("0.2,", "NaN,", 1))),
            LLMSchemaError,
            "final_action.reward_ratio",
        ),
        (
            "responses",
            Reply(200, responses_body(json.dumps({**VALID_AUDIT, "decision": "maybe"}))),
            LLMSchemaError,
            "decision",
        ),
        ("chat", Reply(200, chat_body("not json at all")), LLMSchemaError, "Invalid JSON"),
        ("chat", Reply(200, "<html>gateway</html>"), LLMSchemaError, "not JSON"),
    ],
)
def test_invalid_outputs_raise_typed_errors_naming_the_call_site(api, reply, error, text):
    with FakeOpenAI([reply]) as server, pytest.raises(error) as caught:
        client(server, api).request(MESSAGES, AuditorOutput, SITE)
    message = str(caught.value)
    assert text in message
    assert (
        "policy 'ppo'" in message and "episode 4" in message and "step 7" in message and "run seed 20260511" in message
    )
    assert KEY not in message


@pytest.mark.parametrize("api", APIS)
def test_rate_limit_then_success_is_retried_and_counted(api):
    script = [Reply(429, {"error": {"message": "slow down"}}, {"retry-after-ms": "5"}), ok(path(api), VALID_AUDIT)]
    with FakeOpenAI(script) as server:
        reply = client(server, api, max_retries=2).request(MESSAGES, AuditorOutput, SITE)
    assert len(server.seen) == 2 and reply.meta["retries"] == 1


@pytest.mark.parametrize("api", APIS)
def test_server_errors_until_retries_run_out(api):
    error = Reply(500, {"error": {"message": "boom"}}, {"retry-after-ms": "5"})
    with FakeOpenAI([error] * 5) as server, pytest.raises(LLMTransportError) as caught:
        client(server, api, max_retries=2).request(MESSAGES, AuditorOutput, SITE)
    assert len(server.seen) == 3
    assert "HTTP 500 after 3 attempt(s)" in str(caught.value) and "step 7" in str(caught.value)


def test_timeout_is_a_transport_error():
    with (
        FakeOpenAI([Reply(200, chat_body("{}"), delay_s=2.0)]) as server,
        pytest.raises(LLMTransportError, match="no answer within 0.3 s"),
    ):
        client(server, "chat", timeout_s=0.3, max_retries=0).request(MESSAGES, AuditorOutput, SITE)


def test_unreachable_endpoint_is_a_transport_error():
    settings = resolve_llm_settings(
        api="chat", model="m", base_url="http://127.0.0.1:9/v1", environ={"SOLARCHAIN_LLM_API_KEY": KEY}, max_retries=0
    )
    with pytest.raises(LLMTransportError, match="cannot connect to http://127.0.0.1:9/v1"):
        StructuredLLM(settings).request(MESSAGES, AuditorOutput, SITE)


def test_a_status_the_sdk_does_not_retry_is_reported_as_one_attempt():
    with FakeOpenAI([Reply(401, {"error": {"message": "bad key"}})] * 3) as server:
        with pytest.raises(LLMTransportError) as caught:
            client(server, "chat", max_retries=2).request(MESSAGES, AuditorOutput, SITE)
        assert len(server.seen) == 1  # the SDK does not retry a 401 ...
    assert "HTTP 401 after 1 attempt(s)" in str(caught.value)  # ... and the message does not claim it did


def test_api_key_echoed_by_the_server_is_redacted():
    echo = Reply(401, {"error": {"message": f"Incorrect API key provided: {KEY} (also {KEY[:14]}...)"}})
    with FakeOpenAI([echo]) as server, pytest.raises(LLMTransportError) as caught:
        client(server, "chat").request(MESSAGES, AuditorOutput, SITE)
    message = str(caught.value)
    assert "HTTP 401" in message and KEY not in message and KEY[:14] not in message
    assert "SECRET" not in repr(resolve_llm_settings(api="chat", model="m", environ={"SOLARCHAIN_LLM_API_KEY": KEY}))


def test_settings_resolution_order_and_explicit_api():
    env = {"OPENAI_API_KEY": "k1", "OPENAI_MODEL": "m1", "OPENAI_BASE_URL": "http://127.0.0.1:1/v1"}
    s = resolve_llm_settings(api="responses", environ=env)
    assert (s.model, s.base_url, s.api_key.get_secret_value()) == ("m1", "http://127.0.0.1:1/v1", "k1")
    env.update(SOLARCHAIN_LLM_API_KEY="k2", SOLARCHAIN_LLM_MODEL="m2", SOLARCHAIN_LLM_BASE_URL="http://127.0.0.1:2/v1")
    s = resolve_llm_settings(api="chat", environ=env)
    assert (s.model, s.base_url, s.api_key.get_secret_value()) == ("m2", "http://127.0.0.1:2/v1", "k2")
    s = resolve_llm_settings(api="chat", model="m3", base_url="http://127.0.0.1:3/v1", environ=env)
    assert (s.model, s.base_url) == ("m3", "http://127.0.0.1:3/v1")
    with pytest.raises(LLMConfigError, match="with llm_api responses") as caught:  # the library names the field
        resolve_llm_settings(api=None, environ=env)
    assert "with --llm-api responses" in caught.value.message_for()  # the command line names the flag
    with pytest.raises(LLMConfigError, match="no model"):
        resolve_llm_settings(api="chat", environ={})
    with pytest.raises(LLMConfigError, match="no API key"):
        StructuredLLM(resolve_llm_settings(api="chat", model="m", environ={}))
    described = resolve_llm_settings(
        api="chat", model="m", base_url="http://user:pw@127.0.0.1:5/v1?token=t", environ={}
    ).describe()
    assert described["base_url"] == "http://127.0.0.1:5/v1"


def test_record_then_replay_offline_and_replay_miss(tmp_path):
    cache = tmp_path / "cache"
    with FakeOpenAI([ok("/v1/responses", VALID_AUDIT)]) as server:
        recorded = client(server, "responses", mode="record", cache=cache).request(MESSAGES, AuditorOutput, SITE)
    entries = list(cache.rglob("*.json"))
    assert len(entries) == 1 and entries[0].name == f"{recorded.meta['cache_key']}.json"
    entry = json.loads(entries[0].read_text())
    assert entry["request"]["model"] == "fake-model" and entry["request_id"] == "req-test-1"
    assert entry["usage"] == {"input_tokens": 130, "output_tokens": 45} and entry["retries"] == 0
    assert entry["response"]["output"][1]["content"][0]["text"] == json.dumps(VALID_AUDIT)  # the raw body
    assert entry["latency_s"] == recorded.meta["latency_s"] > 0
    assert KEY not in entries[0].read_text() and "127.0.0.1" not in entries[0].read_text()
    # Replay: the server is gone, and no key is needed (no client is built).
    settings = resolve_llm_settings(api="responses", model="fake-model", base_url="http://127.0.0.1:9/v1", environ={})
    replay = StructuredLLM(settings, cache_dir=cache, cache_mode="replay")
    again = replay.request(MESSAGES, AuditorOutput, SITE)
    assert again.output == recorded.output and again.meta == recorded.meta
    assert replay._client is None
    with pytest.raises(LLMCacheMissError, match="step 7"):
        replay.request(MESSAGES + [{"role": "user", "content": "different"}], AuditorOutput, SITE)


def test_auto_mode_records_misses_and_reuses_entries(tmp_path):
    cache = tmp_path / "cache"
    with FakeOpenAI([ok("/v1/chat/completions", VALID_AUDIT)]) as server:
        llm = client(server, "chat", mode="auto", cache=cache)
        first = llm.request(MESSAGES, AuditorOutput, SITE)
        second = llm.request(MESSAGES, AuditorOutput, SITE)  # a hit: not sent again
    assert len(server.seen) == 1 and first.meta == second.meta
    entry = next(cache.rglob("*.json"))
    before = entry.read_bytes()
    llm.cache.put(first.meta["cache_key"], json.loads(before))  # written once: never replaced
    assert entry.read_bytes() == before


def test_failed_outputs_are_not_recorded(tmp_path):
    cache = tmp_path / "cache"
    with FakeOpenAI([Reply(200, chat_body(None, refusal="no"))]) as server, pytest.raises(LLMRefusalError):
        client(server, "chat", mode="record", cache=cache).request(MESSAGES, AuditorOutput, SITE)
    assert not list(cache.rglob("*.json"))


def test_out_of_range_plan_is_clipped_and_every_clip_logged():
    plan = json.loads(json.dumps(VALID_PLAN))
    plan["action_bounds"]["reward_ratio"] = {"low": 0.9, "high": -1.0}  # swapped and outside
    plan["audit_policy"].update(
        violation_threshold=3.0, gap_threshold=0.4, max_audits_per_episode=99, cooldown_steps=-2
    )
    plan["rationale"] = "x" * 5000
    context = EpisodeContext(0, 24, True, 0.1, -0.2, 0.5, {"max_violation_rate": 0.1})
    with FakeOpenAI([ok("/v1/responses", plan)]) as server:
        outcome = LLMPlanner(client(server, "responses"), CODEC).plan(context, PLANNER_SITE)
    p = outcome.plan
    assert p.bounds[0] == (0.05, 0.65)
    assert (p.violation_threshold, p.gap_threshold, p.max_audits_per_episode, p.cooldown_steps) == (1.0, 0.0, 24, 0)
    assert len(p.rationale) == 2000
    fields = {event["field"] for event in outcome.llm["clipped"]}
    assert fields == {
        "action_bounds.reward_ratio",
        "action_bounds.reward_ratio.low",
        "action_bounds.reward_ratio.high",
        "audit_policy.violation_threshold",
        "audit_policy.gap_threshold",
        "audit_policy.max_audits_per_episode",
        "audit_policy.cooldown_steps",
        "rationale",
    }


def test_out_of_range_audit_action_is_sanitised_and_logged():
    from solarchain_eval.governance.auditor import StepContext
    from solarchain_eval.governance.schemas import validate_plan

    plan = validate_plan(PlannerOutput.model_validate(VALID_PLAN), CODEC, 24)[0]
    audit = dict(VALID_AUDIT, final_action={"reward_ratio": 0.7, "liquidity_ratio": 0.9, "burn_rate": -1.0})
    context = StepContext(
        3, 3, {}, 0.2, 0.0, 0.1, (0.3, 0.5, 0.1), (0.25, 0.75, 0.02), 0.3, plan, ("violation",), True, None
    )
    with FakeOpenAI([ok("/v1/chat/completions", audit)]) as server:
        outcome = LLMAuditor(client(server, "chat"), CODEC).audit(context, SITE)
    alpha, ell = 0.65, 0.9
    scale = 0.98 / (alpha + ell)
    assert outcome.decision == "revise"
    assert outcome.final_action == CODEC.sanitize(0.7, 0.9, -1.0)
    assert math.isclose(outcome.final_action[0], alpha * scale, rel_tol=1e-7) and outcome.final_action[2] == 0.0
    fields = [event["field"] for event in outcome.llm["clipped"]]
    assert fields == [
        "final_action.reward_ratio",
        "final_action.burn_rate",
        "final_action.reward_ratio+liquidity_ratio",
    ]
