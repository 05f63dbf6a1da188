"""Reading raw response bodies of the Chat Completions and Responses APIs.

One function per API turns a response body (a JSON object, exactly as the server sent it and
as the cache stores it) into the structured output, or raises the typed error that says why
it cannot: refusal, truncation, or output that does not match the schema. Live calls and
replays go through the same code, so a replay fails or succeeds exactly as the recording did.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from .errors import LLMRefusalError, LLMSchemaError, LLMTransportError, LLMTruncatedError

T = TypeVar("T", bound=BaseModel)
_SNIPPET_CHARS = 300


@dataclass(frozen=True)
class Usage:
    input_tokens: int | None
    output_tokens: int | None


def _snippet(text: str) -> str:
    text = text.strip()
    return text if len(text) <= _SNIPPET_CHARS else text[:_SNIPPET_CHARS] + "…"


def _validate(text: str, output_type: type[T]) -> T:
    try:
        return output_type.model_validate_json(text)
    except ValidationError as error:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in item['loc']) or '<root>'}: {item['msg']}" for item in error.errors()[:6]
        )
        raise LLMSchemaError(f"{output_type.__name__}: {problems} (output began: {_snippet(text)!r})") from None


def _tokens(usage: Any, key: str) -> int | None:
    value = usage.get(key) if isinstance(usage, dict) else None
    return int(value) if isinstance(value, int) else None


def read_chat(body: Any, output_type: type[T]) -> tuple[T, Usage]:
    """Structured output of a Chat Completions body."""
    if not isinstance(body, dict) or not isinstance(body.get("choices"), list) or not body["choices"]:
        raise LLMSchemaError("the response has no choices (not a Chat Completions response?)")
    choice = body["choices"][0]
    if not isinstance(choice, dict) or not isinstance(choice.get("message"), dict):
        raise LLMSchemaError("the first choice has no message")
    message = choice["message"]
    finish = choice.get("finish_reason")
    if message.get("refusal"):
        raise LLMRefusalError(_snippet(str(message["refusal"])))
    if finish == "length":
        raise LLMTruncatedError("finish_reason 'length'")
    if finish == "content_filter":
        raise LLMRefusalError("finish_reason 'content_filter'")
    content = message.get("content")
    if not isinstance(content, str) or not content.strip():
        raise LLMSchemaError(f"the message has no text content (finish_reason {finish!r})")
    usage = body.get("usage")
    return _validate(content, output_type), Usage(_tokens(usage, "prompt_tokens"), _tokens(usage, "completion_tokens"))


def read_responses(body: Any, output_type: type[T]) -> tuple[T, Usage]:
    """Structured output of a Responses API body."""
    if not isinstance(body, dict) or not isinstance(body.get("output"), list):
        raise LLMSchemaError("the response has no output list (not a Responses API response?)")
    status = body.get("status")
    if status == "incomplete":
        reason = (body.get("incomplete_details") or {}).get("reason")
        if reason == "content_filter":
            raise LLMRefusalError("incomplete: content_filter")
        raise LLMTruncatedError(f"status 'incomplete' (reason {reason!r})")
    if status == "failed":
        error = body.get("error") or {}
        raise LLMTransportError(f"the response failed: {_snippet(str(error.get('message', error)))}")
    texts: list[str] = []
    for item in body["output"]:
        if not isinstance(item, dict) or item.get("type") != "message":
            continue  # reasoning and other items carry no answer
        for part in item.get("content") or []:
            if not isinstance(part, dict):
                continue
            if part.get("type") == "refusal":
                raise LLMRefusalError(_snippet(str(part.get("refusal", ""))))
            if part.get("type") == "output_text" and isinstance(part.get("text"), str):
                texts.append(part["text"])
    text = "".join(texts)
    if not text.strip():
        raise LLMSchemaError(f"the response has no output text (status {status!r})")
    usage = body.get("usage")
    return _validate(text, output_type), Usage(_tokens(usage, "input_tokens"), _tokens(usage, "output_tokens"))


#: ``chat-json-object`` answers in the Chat Completions envelope.
READERS = {"chat": read_chat, "responses": read_responses, "chat-json-object": read_chat}


def reply_usage(api: str, body: Any) -> Usage:
    """The token usage a body reports (also of a reply that was rejected)."""
    usage = body.get("usage") if isinstance(body, dict) else None
    if api == "responses":
        return Usage(_tokens(usage, "input_tokens"), _tokens(usage, "output_tokens"))
    return Usage(_tokens(usage, "prompt_tokens"), _tokens(usage, "completion_tokens"))


def reply_text(api: str, body: Any) -> str | None:
    """The answer text of a body, or None when it has none (to show a model its rejected reply)."""
    if not isinstance(body, dict):
        return None
    if api != "responses":
        choices = body.get("choices")
        message = (
            choices[0].get("message")
            if isinstance(choices, list) and choices and isinstance(choices[0], dict)
            else None
        )
        content = message.get("content") if isinstance(message, dict) else None
        return content if isinstance(content, str) else None
    texts = [
        part["text"]
        for item in body.get("output") or []
        if isinstance(item, dict) and item.get("type") == "message"
        for part in item.get("content") or []
        if isinstance(part, dict) and part.get("type") == "output_text" and isinstance(part.get("text"), str)
    ]
    return "".join(texts) if texts else None
