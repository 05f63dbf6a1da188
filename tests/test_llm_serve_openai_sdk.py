"""``llm serve`` speaks the OpenAI API: the SDK's ``.parse()`` (``json_schema`` response formats)
and OpenAI's HTTP 400 error body for malformed requests.

The middleware (:mod:`solarchain_eval.llm.serving.openai_compat`) is checked in-process on a stub
app; the real server (SmolLM2 behind llama-cpp-python's server, marked ``llm_model``) with the
official ``openai`` SDK and plain ``httpx``. Skipped, with the reason, without the ``llm`` extra.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any, Literal

import httpx
import openai
import pytest
from pydantic import BaseModel, ConfigDict, Field

from solarchain_eval.llm.errors import LLMError
from solarchain_eval.llm.serving import local_server
from solarchain_eval.llm.serving.openai_compat import OpenAICompat

CHAT = "/v1/chat/completions"
MESSAGES = [{"role": "user", "content": "Forecast tomorrow's solar market in Wuhan."}]


class Location(BaseModel):
    city: Literal["Wuhan", "Xian", "Kunming"]
    latitude_deg: float = Field(ge=20, le=40)


class Forecast(BaseModel):
    """A nested model with bounded numbers, an enum, a boolean and a capped string."""

    location: Location
    demand_mwh: float = Field(ge=0, le=100)
    peak_hour: int = Field(ge=0, le=23)
    sunny: bool
    note: str = Field(max_length=24)


class MaybeHour(BaseModel):
    """An optional field (anyOf): no fixed template, so llama.cpp's JSON-schema grammar decodes it."""

    model_config = ConfigDict(extra="forbid")
    hour: int | None


def json_schema_format(schema: dict[str, Any], *, name: str = "X", strict: bool = True) -> dict[str, Any]:
    return {"type": "json_schema", "json_schema": {"name": name, "schema": schema, "strict": strict}}


CLOSED = {"type": "object", "properties": {"a": {"type": "number"}}, "required": ["a"], "additionalProperties": False}
#: Malformed requests: (body, the error's param, words of its message).
MALFORMED = {
    "bad JSON": (b'{"messages": [', None, "could not parse the JSON body"),
    "not an object": (b"[1, 2]", None, "must be a JSON object"),
    "NaN": (b'{"messages": [{"role": "user", "content": "hi"}], "temperature": NaN}', None, "could not parse"),
    "missing messages": ({"model": "m"}, "messages", "Missing required parameter: 'messages'"),
    "empty messages": ({"messages": []}, "messages", "empty array"),
    "messages not a list": ({"messages": "hi"}, "messages", "expected an array, got a string"),
    "unknown format type": (
        {"messages": MESSAGES, "response_format": {"type": "xml"}},
        "response_format.type",
        "Supported values are: 'text', 'json_object' and 'json_schema'",
    ),
    "format not an object": (
        {"messages": MESSAGES, "response_format": "json"},
        "response_format",
        "expected an object",
    ),
    "json_schema missing": (
        {"messages": MESSAGES, "response_format": {"type": "json_schema"}},
        "response_format.json_schema",
        "Missing required parameter",
    ),
    "bad schema name": (
        {"messages": MESSAGES, "response_format": json_schema_format(CLOSED, name="a b")},
        "response_format.json_schema.name",
        "letters, digits",
    ),
    "strict not a boolean": (
        {"messages": MESSAGES, "response_format": {"type": "json_schema", "json_schema": {"name": "X", "strict": "y"}}},
        "response_format.json_schema.strict",
        "expected a boolean",
    ),
    "schema not an object": (
        {"messages": MESSAGES, "response_format": json_schema_format([1])},  # type: ignore[arg-type]
        "response_format",
        "must be a JSON object",
    ),
    "strict schema left open": (
        {"messages": MESSAGES, "response_format": json_schema_format({**CLOSED, "additionalProperties": True})},
        "response_format",
        "'additionalProperties' is required to be supplied and to be false",
    ),
    "strict schema with an optional key": (
        {"messages": MESSAGES, "response_format": json_schema_format({**CLOSED, "required": []})},
        "response_format",
        "Missing 'a'",
    ),
    # the server would answer these with 200 and something else than asked: one choice, or a
    # reply that runs until the context is full
    "n of 3": ({"messages": MESSAGES, "n": 3}, "n", "n must be 1, got 3"),
    "n of 0": ({"messages": MESSAGES, "n": 0}, "n", "n must be 1, got 0"),
    "max_tokens of -1": ({"messages": MESSAGES, "max_tokens": -1}, "max_tokens", "Expected a value >= 1, but got -1"),
    "max_tokens of 0": ({"messages": MESSAGES, "max_tokens": 0}, "max_tokens", "Expected a value >= 1, but got 0"),
    "max_completion_tokens of -1": (
        {"messages": MESSAGES, "max_completion_tokens": -1},
        "max_tokens",
        "Expected a value >= 1, but got -1",
    ),
}
#: Malformed only to the real server: its grammar builder and its request model judge them.
SERVER_MALFORMED = {
    "undecodable schema": (
        {"messages": MESSAGES, "response_format": json_schema_format({"type": "nonsense"}, strict=False)},
        "response_format",
        "cannot be decoded",
    ),
    "temperature not a number": (
        {"messages": MESSAGES, "temperature": "hot"},
        "temperature",
        "Invalid value for 'temperature'",
    ),
    "message without content type": (
        {"messages": [{"role": "user", "content": 5}]},
        "messages.0",
        "Invalid value for 'messages.0'",
    ),
    "max_tokens not an integer": ({"messages": MESSAGES, "max_tokens": "many"}, "max_tokens", "max_tokens"),
    "max_tokens beyond the context": (
        {"messages": MESSAGES, "max_tokens": 10**9},
        "max_tokens",
        f"context window holds {local_server.LOCAL_CONTEXT_TOKENS} tokens",
    ),
}


def _raw(body: Any) -> bytes:
    return body if isinstance(body, bytes) else json.dumps(body).encode()


def _assert_openai_error(response: httpx.Response, param: str | None, words: str) -> None:
    assert response.status_code == 400, response.text
    error = response.json()["error"]
    assert set(error) == {"message", "type", "param", "code"}
    assert error["type"] == "invalid_request_error" and error["code"] is None and error["param"] == param
    assert words in error["message"]


# --- the middleware, in-process ------------------------------------------------------------
async def _echo(scope, receive, send) -> None:
    """A stub server: answers with the body it received and the content-length it was told."""
    body, more = b"", True
    while more:
        message = await receive()
        body, more = body + message.get("body", b""), message.get("more_body", False)
    told = dict(scope["headers"]).get(b"content-length", b"").decode()
    payload = json.dumps({"received": body.decode(), "content_length": told}).encode()
    await send({"type": "http.response.start", "status": 200, "headers": [(b"content-type", b"application/json")]})
    await send({"type": "http.response.body", "body": payload})


def _post(path: str, body: Any, app=None) -> httpx.Response:
    async def go() -> httpx.Response:
        transport = httpx.ASGITransport(app=app or OpenAICompat(_echo))
        async with httpx.AsyncClient(transport=transport, base_url="http://local") as client:
            return await client.post(path, content=_raw(body), headers={"content-type": "application/json"})

    return asyncio.run(go())


def test_a_json_schema_format_reaches_the_server_as_its_json_object_form():
    schema = openai.lib._parsing._completions.type_to_response_format_param(Forecast)
    body = {"model": "m", "messages": MESSAGES, "response_format": schema, "max_completion_tokens": 64}
    answer = _post(CHAT, body).json()
    received = json.loads(answer["received"])
    assert received["response_format"] == {"type": "json_object", "schema": schema["json_schema"]["schema"]}
    assert received["max_tokens"] == 64 and "max_completion_tokens" not in received
    assert received["messages"] == MESSAGES and int(answer["content_length"]) == len(answer["received"].encode())


@pytest.mark.parametrize("fmt", [None, {"type": "text"}, {"type": "json_object", "schema": CLOSED}])
def test_other_formats_and_paths_pass_unchanged(fmt):
    body = {"messages": MESSAGES, "response_format": fmt}
    assert json.loads(_post(CHAT, body).json()["received"]) == body
    assert _post("/v1/other", b"not json").json()["received"] == "not json"  # unchecked path: untouched


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_requests_get_400_with_openais_error_body(case):
    body, param, words = MALFORMED[case]
    _assert_openai_error(_post(CHAT, body), param, words)


def test_max_tokens_the_context_window_cannot_hold_is_refused():
    app = OpenAICompat(_echo, context_tokens=4096)
    for budget in (10**9, 4096):
        for key in ("max_tokens", "max_completion_tokens"):
            response = _post(CHAT, {"messages": MESSAGES, key: budget}, app)
            _assert_openai_error(response, "max_tokens", f"max_tokens is too large: {budget}")
    assert (
        json.loads(_post(CHAT, {"messages": MESSAGES, "max_tokens": 4095}, app).json()["received"])["max_tokens"]
        == 4095
    )
    # the text completions endpoint generates too
    _assert_openai_error(
        _post("/v1/completions", {"prompt": "hi", "max_tokens": 10**9}, app), "max_tokens", "too large"
    )
    _assert_openai_error(_post("/v1/completions", {"prompt": "hi", "n": 2}, app), "n", "n must be 1")
    assert _post("/v1/completions", {"prompt": "hi", "n": 1, "max_tokens": 8}, app).status_code == 200


def test_the_servers_request_model_judges_field_types():
    class Request(BaseModel):
        messages: list[dict[str, Any]]
        temperature: float = 0.0

    app = OpenAICompat(_echo, request_models={CHAT: Request})
    _assert_openai_error(_post(CHAT, {"messages": MESSAGES, "temperature": "hot"}, app), "temperature", "valid number")
    assert _post(CHAT, {"messages": MESSAGES, "temperature": 0.5}, app).status_code == 200


# --- the real server -----------------------------------------------------------------------
@pytest.fixture(scope="module")
def server():
    if not local_server.llama_cpp_available():
        pytest.skip("llama_cpp is not importable: pip install -e '.[llm]'")
    try:
        path = local_server.default_model_path()
    except LLMError as error:
        pytest.skip(str(error))
    spec = local_server.ServerSpec(
        model_path=path, model_name=local_server.default_model_name(), requantize=local_server.DEFAULT_FILE_TYPE
    )
    with local_server.LocalServer(spec) as running:
        pid = running.process.pid
        yield running
    assert not local_server.pid_alive(pid)


@pytest.fixture(scope="module")
def sdk(server):
    client = openai.OpenAI(base_url=server.base_url, api_key="none", max_retries=0, timeout=300)
    yield client
    client.close()


@pytest.mark.llm_model
def test_the_sdks_parse_returns_an_object_valid_under_the_schema(server, sdk):
    completion = sdk.beta.chat.completions.parse(
        model=server.spec.model_name, messages=MESSAGES, response_format=Forecast, temperature=0
    )
    choice = completion.choices[0]
    parsed = choice.message.parsed
    assert choice.finish_reason == "stop" and isinstance(parsed, Forecast)
    assert Forecast.model_validate_json(choice.message.content) == parsed  # bounds and all
    assert 0 <= parsed.demand_mwh <= 100 and 0 <= parsed.peak_hour <= 23 and 20 <= parsed.location.latitude_deg <= 40
    # an optional field has no fixed layout: the grammar path answers it, as valid
    other = sdk.beta.chat.completions.parse(
        model=server.spec.model_name,
        messages=[{"role": "user", "content": "At which hour does the sun rise?"}],
        response_format=MaybeHour,
        temperature=0,
        max_completion_tokens=32,
    )
    assert isinstance(other.choices[0].message.parsed, MaybeHour)


@pytest.mark.llm_model
@pytest.mark.parametrize("case", [*MALFORMED, *SERVER_MALFORMED])
def test_the_server_answers_malformed_requests_with_400_and_openais_error_body(server, case):
    body, param, words = {**MALFORMED, **SERVER_MALFORMED}[case]
    response = httpx.post(
        f"{server.base_url}/chat/completions", content=_raw(body), headers={"content-type": "application/json"}
    )
    _assert_openai_error(response, param, words)


@pytest.mark.llm_model
def test_other_endpoints_answer_bad_bodies_with_400_too(server):
    cases = (
        ("/completions", {"prompt": 5}, "prompt"),
        ("/embeddings", b"{", None),
        ("/completions", {"prompt": "hi", "n": 3}, "n"),
        ("/completions", {"prompt": "hi", "max_tokens": -1}, "max_tokens"),
        ("/completions", {"prompt": "hi", "max_tokens": 10**9}, "max_tokens"),
    )
    for path, body, param in cases:
        response = httpx.post(
            f"{server.base_url}{path}", content=_raw(body), headers={"content-type": "application/json"}
        )
        assert response.status_code == 400 and response.json()["error"]["param"] == param
