"""A tiny OpenAI-compatible server on 127.0.0.1 for offline tests.

It speaks ``POST /v1/chat/completions`` and ``POST /v1/responses``. Answers come from a script
(a list of :class:`Reply`, consumed in order) or, when the script is empty, from a responder
function. Every request is recorded (path, headers, JSON body).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

VALID_PLAN = {
    "governance_mode": "llm_guarded",
    "action_bounds": {
        "reward_ratio": {"low": 0.05, "high": 0.5},
        "liquidity_ratio": {"low": 0.3, "high": 0.9},
        "burn_rate": {"low": 0.01, "high": 0.18},
    },
    "audit_policy": {
        "violation_threshold": 0.1,
        "gap_threshold": -0.2,
        "jitter_threshold": 0.2,
        "slippage_threshold": 2.0,
        "max_audits_per_episode": 5,
        "target_audit_rate": 0.2,
        "cooldown_steps": 1,
    },
    "rationale": "Moderate risk: keep allocations away from the cap.",
}

VALID_AUDIT = {
    "decision": "revise",
    "final_action": {"reward_ratio": 0.2, "liquidity_ratio": 0.6, "burn_rate": 0.1},
    "risk_assessment": {"physics": "high", "liquidity": "low", "jitter": "medium", "fairness": "unknown"},
    "reason": "Violation rate above threshold; tighten allocation.",
}


@dataclass
class Reply:
    status: int = 200
    body: Any = None  # dict (sent as JSON) or str (sent as is)
    headers: dict[str, str] = field(default_factory=dict)
    delay_s: float = 0.0
    drip_s: float = 0.0  # send the body one byte at a time, this many seconds apart


@dataclass
class Seen:
    path: str
    headers: dict[str, str]
    body: dict[str, Any]


def schema_name(path: str, body: dict[str, Any]) -> str:
    if path.endswith("/chat/completions"):
        return body["response_format"]["json_schema"]["name"]
    return body["text"]["format"]["name"]


def user_context(path: str, body: dict[str, Any]) -> dict[str, Any]:
    """The JSON context the prompt templates put after 'Context (JSON):'."""
    messages = body["messages"] if path.endswith("/chat/completions") else body["input"]
    text = messages[-1]["content"]
    return json.loads(text.split("Context (JSON):\n", 1)[1])


def chat_body(
    content: str | None, *, finish_reason: str = "stop", refusal: str | None = None, model: str = "fake-model"
) -> dict:
    return {
        "id": "chatcmpl-1",
        "object": "chat.completion",
        "created": 0,
        "model": model,
        "choices": [
            {
                "index": 0,
                "finish_reason": finish_reason,
                "message": {"role": "assistant", "content": content, "refusal": refusal},
            }
        ],
        "usage": {"prompt_tokens": 120, "completion_tokens": 40, "total_tokens": 160},
    }


def responses_body(
    text: str | None,
    *,
    status: str = "completed",
    refusal: str | None = None,
    incomplete_reason: str | None = None,
    model: str = "fake-model",
) -> dict:
    content: list[dict[str, Any]] = []
    if refusal is not None:
        content.append({"type": "refusal", "refusal": refusal})
    if text is not None:
        content.append({"type": "output_text", "text": text, "annotations": []})
    return {
        "id": "resp_1",
        "object": "response",
        "created_at": 0,
        "status": status,
        "model": model,
        "incomplete_details": {"reason": incomplete_reason} if incomplete_reason else None,
        "output": [
            {"type": "reasoning", "id": "rs_1", "summary": []},
            {"type": "message", "id": "msg_1", "status": "completed", "role": "assistant", "content": content},
        ],
        "usage": {"input_tokens": 130, "output_tokens": 45, "total_tokens": 175},
    }


def ok(path: str, payload: dict | str) -> Reply:
    """A successful answer carrying ``payload`` (dict -> JSON text) in the API's envelope."""
    text = payload if isinstance(payload, str) else json.dumps(payload)
    body = chat_body(text) if path.endswith("/chat/completions") else responses_body(text)
    return Reply(200, body, {"x-request-id": "req-test-1"})


def default_responder(seen: Seen) -> Reply:
    """Valid plans; audits that revise on even steps and approve (echoing ā) on odd ones."""
    if schema_name(seen.path, seen.body) == "PlannerOutput":
        return ok(seen.path, VALID_PLAN)
    context = user_context(seen.path, seen.body)
    if context["step"] % 2 == 0:
        return ok(seen.path, VALID_AUDIT)
    audit = dict(VALID_AUDIT, decision="approve", final_action=context["bounded_proposed_action"], reason="fine")
    return ok(seen.path, audit)


class FakeOpenAI:
    """Run with ``with FakeOpenAI(...) as server:``; ``server.base_url`` ends in ``/v1``."""

    def __init__(
        self, script: list[Reply] | None = None, responder: Callable[[Seen], Reply] = default_responder
    ) -> None:
        self.script = list(script or [])
        self.responder = responder
        self.seen: list[Seen] = []
        self._lock = threading.Lock()
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args: Any) -> None:  # keep test output clean
                return

            def do_POST(self) -> None:  # noqa: N802 (http.server API)
                length = int(self.headers.get("content-length", 0))
                raw = self.rfile.read(length)
                seen = Seen(self.path, {k.lower(): v for k, v in self.headers.items()}, json.loads(raw or b"{}"))
                with outer._lock:
                    outer.seen.append(seen)
                    reply = outer.script.pop(0) if outer.script else None
                if reply is None:
                    if self.path not in ("/v1/chat/completions", "/v1/responses"):
                        reply = Reply(404, {"error": {"message": f"no route {self.path}"}})
                    else:
                        reply = outer.responder(seen)
                if reply.delay_s:
                    time.sleep(reply.delay_s)
                payload = reply.body if isinstance(reply.body, str) else json.dumps(reply.body)
                data = payload.encode("utf-8")
                try:
                    self.send_response(reply.status)
                    self.send_header("content-type", "application/json")
                    self.send_header("content-length", str(len(data)))
                    for key, value in reply.headers.items():
                        self.send_header(key, value)
                    self.end_headers()
                    if reply.drip_s:
                        for i in range(len(data)):
                            self.wfile.write(data[i : i + 1])
                            self.wfile.flush()
                            time.sleep(reply.drip_s)
                    else:
                        self.wfile.write(data)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the client gave up (timeout tests)

        self._server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.01}, daemon=True)

    @property
    def base_url(self) -> str:
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}/v1"

    def __enter__(self) -> FakeOpenAI:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=5)
