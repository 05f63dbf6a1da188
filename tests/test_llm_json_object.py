"""The chat-json-object mode (llama-cpp-python's server) and the local backend's settings,
against the scripted server on 127.0.0.1 (no model needed)."""

from __future__ import annotations

import json
import re

import pytest

from fake_openai import VALID_AUDIT, VALID_PLAN, FakeOpenAI, Reply, chat_body, ok
from solarchain_eval.cli import agentic as agentic_cli
from solarchain_eval.cli.common import CliError
from solarchain_eval.governance.schemas import SCHEMA_TEXT_MAX_CHARS, AuditorOutput, PlannerOutput
from solarchain_eval.llm import CallSite, LLMSchemaError, StructuredLLM, resolve_llm_settings
from solarchain_eval.llm.response_format import SCHEMA_TEXT_CHARS, response_format
from solarchain_eval.llm.serving import local_server

SITE = CallSite("auditor", "sac", 7, 3, 11)
MESSAGES = [{"role": "system", "content": "s"}, {"role": "user", "content": 'Context (JSON):\n{"step": 11}'}]
CHAT = "/v1/chat/completions"


def json_object_client(server: FakeOpenAI, **kw) -> StructuredLLM:
    settings = resolve_llm_settings(
        api="chat-json-object",
        model="local-model",
        base_url=server.base_url,
        environ={"SOLARCHAIN_LLM_API_KEY": "x"},
        **kw,
    )
    return StructuredLLM(settings)


def test_json_object_request_carries_the_capped_schema_max_tokens_and_seed():
    with FakeOpenAI([ok(CHAT, VALID_PLAN)]) as server:
        reply = json_object_client(server, max_output_tokens=321, temperature=0.0, seed=5).request(
            MESSAGES, PlannerOutput, SITE
        )
    assert reply.output == PlannerOutput.model_validate(VALID_PLAN)
    (seen,) = server.seen
    fmt = seen.body["response_format"]
    assert fmt["type"] == "json_object" and set(fmt) == {"type", "schema"}
    schema = fmt["schema"]
    # the same strict schema the chat mode sends, plus maxLength and a pattern on the free text
    strict = response_format(PlannerOutput, "chat")["json_schema"]["schema"]
    limit = SCHEMA_TEXT_MAX_CHARS["rationale"]
    assert schema["properties"]["rationale"] == {
        **strict["properties"]["rationale"],
        "maxLength": limit,
        "pattern": f"^{SCHEMA_TEXT_CHARS}{{0,{limit}}}$",
    }
    assert schema["properties"]["governance_mode"]["maxLength"] == SCHEMA_TEXT_MAX_CHARS["governance_mode"]
    assert schema["$defs"] == strict["$defs"] and schema["required"] == strict["required"]
    assert seen.body["max_tokens"] == 321 and "max_completion_tokens" not in seen.body
    assert seen.body["seed"] == 5 and seen.body["temperature"] == 0.0
    audit_schema = response_format(AuditorOutput, "chat-json-object")["schema"]
    assert audit_schema["properties"]["reason"]["maxLength"] == SCHEMA_TEXT_MAX_CHARS["reason"]


def test_free_text_pattern_admits_printable_text_only():
    # llama-cpp-python's grammar for a plain string admits raw control characters (invalid JSON);
    # the pattern, which its grammar compiler prefers, must not.
    pattern = re.compile(
        response_format(AuditorOutput, "chat-json-object")["schema"]["properties"]["reason"]["pattern"]
    )
    limit = SCHEMA_TEXT_MAX_CHARS["reason"]
    assert pattern.fullmatch("Violation rate 0.30 > 0.01; cut alpha (-15%), keep l.")
    assert pattern.fullmatch("x" * limit) and not pattern.fullmatch("x" * (limit + 1))
    for bad in ("line\nbreak", "tab\there", 'a "quote"', "back\\slash", "caf\u00e9", "nul\x00"):
        assert not pattern.fullmatch(bad), repr(bad)


def test_seed_is_part_of_the_cache_key_only_when_set():
    settings = resolve_llm_settings(api="chat-json-object", model="m", environ={})
    plain = StructuredLLM.__new__(StructuredLLM)
    plain.settings = settings
    seeded = StructuredLLM.__new__(StructuredLLM)
    seeded.settings = resolve_llm_settings(api="chat-json-object", model="m", environ={}, seed=0)
    assert "seed" not in plain.canonical_request(MESSAGES, AuditorOutput)["parameters"]
    assert seeded.canonical_request(MESSAGES, AuditorOutput)["parameters"]["seed"] == 0


@pytest.mark.parametrize(
    ("content", "text"),
    [
        ("Sure! I approve this action because it looks fine.", "Invalid JSON"),
        (json.dumps({"decision": "approve"}), "final_action: Field required"),
        (json.dumps({**VALID_AUDIT, "decision": "escalate"}), "decision"),
    ],
)
def test_a_server_that_ignores_the_schema_is_a_typed_failure_naming_episode_and_step(content, text):
    with FakeOpenAI([Reply(200, chat_body(content))]) as server, pytest.raises(LLMSchemaError) as caught:
        json_object_client(server).request(MESSAGES, AuditorOutput, SITE)
    message = str(caught.value)
    assert text in message and "episode 3" in message and "step 11" in message and "policy 'sac'" in message


def local_params(**overrides):
    params = dict(
        agentic="planner_auditor",
        llm_backend="local",
        planner="llm",
        auditor="rule",
        llm_api=None,
        llm_model=None,
        llm_base_url=None,
        llm_temperature=None,
        llm_timeout=30.0,
        llm_max_retries=0,
        llm_max_output_tokens=4096,
        llm_cache=None,
        llm_cache_mode=None,
    )
    params.update(overrides)
    return params


def test_local_backend_settings_need_no_key_and_pin_api_temperature_seed(tmp_path, monkeypatch):
    for name in ("SOLARCHAIN_LLM_API_KEY", "OPENAI_API_KEY", "SOLARCHAIN_LLM_MODEL", "OPENAI_MODEL"):
        monkeypatch.delenv(name, raising=False)
    gguf = tmp_path / "tiny-model.gguf"
    gguf.write_bytes(b"GGUF")
    params = local_params(llm_model=str(gguf))
    options = agentic_cli.agentic_options(**params)
    s = options.llm.settings
    assert (s.api, s.model, s.temperature, s.seed) == ("chat-json-object", "tiny-model", 0.0, local_server.LOCAL_SEED)
    assert s.max_output_tokens == local_server.LOCAL_MAX_OUTPUT_TOKENS
    assert s.base_url.startswith("http://127.0.0.1:") and s.base_url.endswith("/v1")
    spec = agentic_cli.local_server_spec(params, options)
    assert (
        spec.model_path == gguf and spec.model_name == "tiny-model" and s.base_url == f"http://127.0.0.1:{spec.port}/v1"
    )
    # one request slot per episode in flight (evaluate's --llm-concurrency)
    assert spec.parallel == 1 and agentic_cli.local_server_spec({**params, "llm_concurrency": 3}, options).parallel == 3
    # a replay starts no server; the remote backend never does
    replay = local_params(llm_model=str(gguf), llm_cache=tmp_path / "c", llm_cache_mode="replay")
    assert agentic_cli.local_server_spec(replay, agentic_cli.agentic_options(**replay)) is None
    assert agentic_cli.local_server_spec(local_params(llm_backend="remote"), options) is None


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"llm_api": "chat"}, "needs --llm-api chat-json-object"),
        ({"llm_base_url": "http://127.0.0.1:9/v1"}, "--llm-base-url is for --llm-backend remote"),
        ({"llm_model": "/no/such/model.gguf"}, "no such GGUF file"),
        ({"llm_backend": "cloud"}, "--llm-backend must be one of"),
    ],
)
def test_local_backend_rejects_inconsistent_flags(overrides, message):
    with pytest.raises((CliError, Exception)) as caught:
        agentic_cli.agentic_options(**local_params(**overrides))
    assert message in str(caught.value)
