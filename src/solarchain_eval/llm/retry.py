"""Asking again after a reply that does not validate (``StructuredLLM.request(invalid_retries=N)``).

A reply outside the schema's rules (a number out of its range, a missing field) is an
:class:`~.errors.LLMSchemaError`. With retries allowed, the model is asked again: the same
request followed by its rejected reply and a user message naming the problem, so that a
deterministic server (temperature 0, a seed) gets a different request and can answer
differently. The whole exchange becomes one cache entry under the original request's key: the
accepted answer plus every rejected reply (``rejected``), with the latency and retries of all
attempts, so a replay gives the same output, retry count and token totals as the recording.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pydantic import BaseModel

from .envelopes import READERS, reply_text, reply_usage
from .errors import LLMSchemaError


def exchange(
    call: Callable[[dict[str, Any]], dict[str, Any]],
    request: dict[str, Any],
    api: str,
    output_type: type[BaseModel],
    invalid_retries: int,
) -> dict[str, Any]:
    """The cache entry of ``request``: the endpoint's accepted answer after at most
    ``invalid_retries`` rejected ones.

    Parameters
    ----------
    call : callable
        Sends one request and returns its entry (response, latency, retries, ...).
    request : dict
        The canonical request (its messages are extended for each new attempt).
    api : str
        Which envelope the responses come in.
    output_type : pydantic model class
    invalid_retries : int
        New attempts after a reply that does not validate (0: none).

    Raises
    ------
    LLMSchemaError
        The last reply did not validate either (the message says how many were rejected).
    """
    attempt, rejected = request, []
    while True:
        entry = call(attempt)
        try:
            _, usage = READERS[api](entry["response"], output_type)
            break
        except LLMSchemaError as error:
            if len(rejected) >= invalid_retries:
                if rejected:
                    raise LLMSchemaError(f"{error.detail} (reply {len(rejected) + 1}, every one rejected)") from None
                raise
            used = reply_usage(api, entry["response"])
            rejected.append(
                {
                    "problem": error.detail,
                    "response": entry["response"],
                    "latency_s": entry["latency_s"],
                    "retries": entry["retries"],
                    "usage": {"input_tokens": used.input_tokens, "output_tokens": used.output_tokens},
                }
            )
            attempt = with_feedback(request, reply_text(api, entry["response"]), error.detail)
    entry["usage"] = {"input_tokens": usage.input_tokens, "output_tokens": usage.output_tokens}
    if rejected:  # one exchange under the request's key: the time and retries of all attempts
        entry["request"] = request
        entry["latency_s"] = round(entry["latency_s"] + sum(r["latency_s"] for r in rejected), 6)
        entry["retries"] = int(entry["retries"]) + sum(int(r["retries"]) + 1 for r in rejected)
        entry["rejected"] = rejected
    return entry


def with_feedback(request: dict[str, Any], reply: str | None, problem: str) -> dict[str, Any]:
    """``request`` followed by the rejected reply (when it had text) and what was wrong with it."""
    feedback = [{"role": "assistant", "content": reply}] if reply else []
    feedback.append(
        {
            "role": "user",
            "content": f"That reply was rejected: {problem}. Answer again, following the response schema exactly.",
        }
    )
    return {**request, "messages": [*request["messages"], *feedback]}


def total_tokens(accepted: int | None, rejected: list[int | None]) -> int | None:
    """Tokens of all attempts (None when the server reported none for the accepted one)."""
    return None if accepted is None else accepted + sum(n or 0 for n in rejected)
