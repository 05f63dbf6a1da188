"""OpenAI's request checks and ``json_schema`` response formats in front of llama-cpp-python's server.

llama-cpp-python's server knows two response formats, ``text`` and ``json_object`` (with an
optional ``schema``), and answers any request it cannot read (bad JSON, a ``json_schema`` format
as the OpenAI SDK's ``.parse()`` sends it, a missing or mistyped field) with HTTP 500.
:class:`OpenAICompat` is an ASGI middleware in front of it that makes it behave like the OpenAI
API for these requests:

- ``response_format: {"type": "json_schema", "json_schema": {"name", "schema", "strict"}}`` is
  checked (a name of letters, digits, ``_`` and ``-``; a schema object; with ``strict`` every
  object closed and every property required, as OpenAI demands) and handed to the server as
  ``{"type": "json_object", "schema": ...}``, the form its decoders read: jump-forward decoding
  (:mod:`.jump_forward`) when the schema is a fixed template, llama.cpp's JSON-schema grammar
  otherwise. A schema the grammar builder cannot compile is refused before any decoding.
- ``max_completion_tokens`` (what the SDK sends for a token budget) becomes ``max_tokens``.
- ``n`` other than 1 is refused (the server returns one choice whatever ``n`` asks), and so is a
  ``max_tokens`` below 1 (llama.cpp reads it as "until the context is full") or one the context
  window cannot hold (``max_tokens`` at least the window, which also holds the prompt).
- A malformed request is answered with HTTP 400 and OpenAI's error body
  ``{"error": {"message", "type": "invalid_request_error", "param", "code": null}}``, never 500.

The checks here need nothing from llama-cpp-python: the server passes its own request models
and its grammar builder in (:func:`llama_cpp_checks`), so a request this layer lets through is
one the server reads.
"""

from __future__ import annotations

import json
import re
from collections.abc import Awaitable, Callable, Mapping
from typing import Any

from pydantic import BaseModel, ValidationError

from ...common.errors import InputDataError

CHAT_PATH = "/v1/chat/completions"
#: The JSON endpoints whose bodies are checked: the chat endpoint, and those with a request model.
CHECKED_PATHS = (CHAT_PATH, "/v1/completions", "/v1/embeddings")
#: The endpoints that generate text (``n`` and ``max_tokens`` are checked).
GENERATING_PATHS = (CHAT_PATH, "/v1/completions")
RESPONSE_FORMAT_TYPES = ("text", "json_object", "json_schema")
#: OpenAI's rule for a response format's name.
SCHEMA_NAME = re.compile(r"[a-zA-Z0-9_-]{1,64}\Z")

Scope = dict[str, Any]
Receive = Callable[[], Awaitable[dict[str, Any]]]
Send = Callable[[dict[str, Any]], Awaitable[None]]


class InvalidRequest(InputDataError, ValueError):
    """A request the API refuses: ``message`` says why, ``param`` names the field (or None)."""

    def __init__(self, message: str, param: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.param = param

    def body(self) -> dict[str, Any]:
        """OpenAI's error body."""
        return {"error": {"message": self.message, "type": "invalid_request_error", "param": self.param, "code": None}}


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON")


def parse_body(raw: bytes) -> dict[str, Any]:
    """The request's JSON object (strict JSON: no NaN or Infinity)."""
    try:
        body = json.loads(raw.decode("utf-8"), parse_constant=_refuse_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as error:
        raise InvalidRequest(f"We could not parse the JSON body of your request: {error}") from None
    if not isinstance(body, dict):
        raise InvalidRequest(f"The request body must be a JSON object, got {type(body).__name__}.")
    return body


def chat_request(body: dict[str, Any], check_schema: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """A Chat Completions body checked and rewritten for llama-cpp-python's server.

    Parameters
    ----------
    body : dict
        The parsed request.
    check_schema : callable, optional
        Raises (any exception) when the server cannot decode under a JSON schema.

    Raises
    ------
    InvalidRequest
        Missing or empty ``messages``, an unknown response format, an invalid ``json_schema``.
    """
    if "messages" not in body:
        raise InvalidRequest("Missing required parameter: 'messages'.", "messages")
    if not isinstance(body["messages"], list):
        raise InvalidRequest(
            f"Invalid type for 'messages': expected an array, got {_json_type(body['messages'])}.", "messages"
        )
    if not body["messages"]:
        raise InvalidRequest("Invalid 'messages': empty array. Expected an array with minimum length 1.", "messages")
    out = dict(body)
    if "max_completion_tokens" in out:
        budget = out.pop("max_completion_tokens")
        out.setdefault("max_tokens", budget)
    if out.get("response_format") is not None:
        out["response_format"] = response_format(out["response_format"], check_schema)
    return out


def check_choices_and_budget(body: dict[str, Any], context_tokens: int | None = None) -> None:
    """Refuse what the server would answer with 200 and a reply other than the one asked for:
    ``n`` other than 1 (it returns one choice), ``max_tokens`` below 1 (llama.cpp decodes until
    the context is full) or at least ``context_tokens`` (the window holds the prompt too).

    Values of other types are left to the server's request model, which names their type.
    """
    n = body.get("n")
    if _is_number(n) and n != 1:
        raise InvalidRequest(
            f"Invalid value for 'n': this server returns one choice per request, so n must be 1, got {n}.", "n"
        )
    budget = body.get("max_tokens")
    if not _is_number(budget):
        return
    if budget < 1:
        raise InvalidRequest(
            f"Invalid 'max_tokens': integer below minimum value. Expected a value >= 1, but got {budget} instead.",
            "max_tokens",
        )
    if context_tokens is not None and context_tokens > 0 and budget >= context_tokens:
        raise InvalidRequest(
            f"max_tokens is too large: {budget}. This model's context window holds {context_tokens} tokens, "
            f"prompt and completion together, whereas you provided {budget}.",
            "max_tokens",
        )


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def response_format(value: Any, check_schema: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """The server's form of a response format (``json_schema`` becomes ``json_object`` + schema)."""
    if not isinstance(value, dict):
        raise InvalidRequest(
            f"Invalid type for 'response_format': expected an object, got {_json_type(value)}.", "response_format"
        )
    kind = value.get("type")
    if kind not in RESPONSE_FORMAT_TYPES:
        got = f"'{kind}'" if isinstance(kind, str) else json.dumps(kind)
        raise InvalidRequest(
            f"Invalid value: {got}. Supported values are: 'text', 'json_object' and 'json_schema'.",
            "response_format.type",
        )
    if kind != "json_schema":
        return value
    spec = value.get("json_schema")
    param = "response_format.json_schema"
    if spec is None:
        raise InvalidRequest(f"Missing required parameter: '{param}'.", param)
    if not isinstance(spec, dict):
        raise InvalidRequest(f"Invalid type for '{param}': expected an object, got {_json_type(spec)}.", param)
    name = spec.get("name")
    if not isinstance(name, str) or SCHEMA_NAME.match(name) is None:
        raise InvalidRequest(
            f"Invalid '{param}.name': {json.dumps(name)} must be 1-64 letters, digits, underscores or dashes.",
            f"{param}.name",
        )
    strict = spec.get("strict")
    if strict is not None and not isinstance(strict, bool):
        raise InvalidRequest(
            f"Invalid type for '{param}.strict': expected a boolean, got {_json_type(strict)}.", f"{param}.strict"
        )
    if "schema" not in spec:
        return {"type": "json_object"}
    schema = spec["schema"]
    if not isinstance(schema, dict):
        raise InvalidRequest(
            f"Invalid schema for response_format '{name}': the schema must be a JSON object, got {_json_type(schema)}.",
            "response_format",
        )
    if strict:
        problem = strict_problem(schema)
        if problem is not None:
            raise InvalidRequest(f"Invalid schema for response_format '{name}': {problem}", "response_format")
    if check_schema is not None:
        try:
            check_schema(schema)
        except Exception as error:  # the grammar builder raises assertions, KeyErrors, ...
            detail = str(error) or type(error).__name__
            raise InvalidRequest(
                f"Invalid schema for response_format '{name}': it cannot be decoded ({detail}).", "response_format"
            ) from None
    return {"type": "json_object", "schema": schema}


def strict_problem(schema: Any, context: tuple[str | int, ...] = ()) -> str | None:
    """Why ``schema`` breaks OpenAI's strict-mode rules (None: it keeps them): every object must
    set ``additionalProperties: false`` and list every property in ``required``."""
    if isinstance(schema, list):
        for index, item in enumerate(schema):
            found = strict_problem(item, (*context, index))
            if found is not None:
                return found
        return None
    if not isinstance(schema, dict):
        return None
    properties = schema.get("properties")
    if schema.get("type") == "object" or isinstance(properties, dict):
        where = f"In context={context}, "
        if schema.get("additionalProperties") is not False:
            return f"{where}'additionalProperties' is required to be supplied and to be false."
        keys = list(properties) if isinstance(properties, dict) else []
        required = schema.get("required")
        missing = [key for key in keys if not isinstance(required, list) or key not in required]
        if missing:
            return (
                f"{where}'required' is required to be supplied and to be an array including every key in "
                f"properties. Missing '{missing[0]}'."
            )
    for key, value in schema.items():
        if key in ("properties", "$defs", "definitions") and isinstance(value, dict):
            for name, sub in value.items():
                found = strict_problem(sub, (*context, key, name))
                if found is not None:
                    return found
        elif key in ("items", "anyOf", "allOf", "oneOf", "prefixItems"):
            found = strict_problem(value, (*context, key))
            if found is not None:
                return found
    return None


def validation_problem(error: ValidationError, body: Any) -> InvalidRequest:
    """The first problem of a request model's validation, as OpenAI words it; ``param`` is the
    path of fields and indices that exist in ``body`` (pydantic's location also names union
    branches and validators, which are no fields of the request)."""
    item = error.errors()[0]
    loc, parts, node = list(item["loc"]), [], body
    for index, part in enumerate(loc):
        in_dict = isinstance(node, dict) and isinstance(part, str) and part in node
        if in_dict or (isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node)):
            node = node[part]
        elif item["type"] == "missing" and index == len(loc) - 1 and isinstance(node, dict):
            parts.append(str(part))
            break
        else:
            break
        parts.append(str(part))
    param = ".".join(parts) or None
    if item["type"] == "missing":
        return InvalidRequest(f"Missing required parameter: '{param}'.", param)
    return InvalidRequest(f"Invalid value for '{param}': {item['msg']}.", param)


def _json_type(value: Any) -> str:
    names = {dict: "an object", list: "an array", str: "a string", bool: "a boolean", type(None): "null"}
    if isinstance(value, bool | dict | list | str) or value is None:
        return names[type(value)]
    return "a number"


class OpenAICompat:
    """ASGI middleware: OpenAI's request checks and ``json_schema`` formats for the wrapped server.

    Parameters
    ----------
    app : ASGI application
        llama-cpp-python's server app.
    request_models : mapping of path -> pydantic model, optional
        The server's request model of each endpoint: a body it refuses is answered with 400.
    check_schema : callable, optional
        Raises when the server cannot decode under a ``json_schema`` format's schema.
    context_tokens : int, optional
        The model's context window: a ``max_tokens`` this large is refused (None: not checked).
    """

    def __init__(
        self,
        app: Callable[[Scope, Receive, Send], Awaitable[None]],
        *,
        request_models: Mapping[str, type[BaseModel]] | None = None,
        check_schema: Callable[[dict[str, Any]], None] | None = None,
        context_tokens: int | None = None,
    ) -> None:
        self.app = app
        self.request_models = dict(request_models or {})
        self.check_schema = check_schema
        self.context_tokens = context_tokens

    def check(self, path: str, raw: bytes) -> dict[str, Any]:
        """The body the server gets for ``raw`` sent to ``path``; raises :class:`InvalidRequest`."""
        body = parse_body(raw)
        if path == CHAT_PATH:
            body = chat_request(body, self.check_schema)
        if path in GENERATING_PATHS:
            check_choices_and_budget(body, self.context_tokens)
        model = self.request_models.get(path)
        if model is not None:
            try:
                model.model_validate(body)
            except ValidationError as error:
                raise validation_problem(error, body) from None
        return body

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] not in CHECKED_PATHS:
            await self.app(scope, receive, send)
            return
        chunks = []
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                return  # the client left before the body arrived: nobody to answer
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                break
        try:
            body = self.check(scope["path"], b"".join(chunks))
        except InvalidRequest as problem:
            await _send_json(send, 400, problem.body())
            return
        payload = json.dumps(body, ensure_ascii=False).encode("utf-8")
        headers = [(k, v) for k, v in scope.get("headers", []) if k.lower() != b"content-length"]
        headers.append((b"content-length", str(len(payload)).encode("ascii")))
        delivered = False

        async def replay() -> dict[str, Any]:
            nonlocal delivered
            if delivered:
                return await receive()  # later reads wait for the client's disconnect, as before
            delivered = True
            return {"type": "http.request", "body": payload, "more_body": False}

        await self.app({**scope, "headers": headers}, replay, send)


async def _send_json(send: Send, status: int, body: dict[str, Any]) -> None:
    payload = json.dumps(body).encode("utf-8")
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(payload)).encode("ascii"))]
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": payload, "more_body": False})


def llama_cpp_checks() -> dict[str, Any]:
    """:class:`OpenAICompat`'s keyword arguments for llama-cpp-python's server: its request models
    and its JSON-schema grammar builder (imported here: the server needs llama-cpp-python)."""
    from llama_cpp.llama_grammar import json_schema_to_gbnf
    from llama_cpp.server.types import CreateChatCompletionRequest, CreateCompletionRequest, CreateEmbeddingRequest

    def check_schema(schema: dict[str, Any]) -> None:
        json_schema_to_gbnf(json.dumps(schema))

    return {
        "request_models": {
            CHAT_PATH: CreateChatCompletionRequest,
            "/v1/completions": CreateCompletionRequest,
            "/v1/embeddings": CreateEmbeddingRequest,
        },
        "check_schema": check_schema,
    }
