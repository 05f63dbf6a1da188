"""An httpx transport that bounds the total time of each HTTP attempt.

httpx's timeouts (the openai SDK's HTTP layer) bound each network operation (connect, one read, one write), not a whole
request: a server that sends one byte every 0.5 s never trips a 2 s read timeout and can hold
a call for ever. :class:`DeadlineTransport` sends the request and reads the whole body in a
helper thread and waits for it at most ``timeout_s``; past that it raises
``ReadTimeout``, which the openai SDK treats as any timeout (retried up to
``max_retries`` times, then ``APITimeoutError``). The abandoned helper stops at its next chunk
(or at the read timeout) and closes its connection. See docs/output_safety.md.
"""

from __future__ import annotations

import importlib
import threading
from types import ModuleType
from typing import Any


def sdk_http_module() -> ModuleType:
    """The httpx package the installed openai SDK is built on (``httpx``, or its fork ``httpx2``)."""
    import openai

    client_base = openai.DefaultHttpxClient.__mro__[1]
    return importlib.import_module(client_base.__module__.split(".")[0])


class DeadlineTransport:
    """An httpx transport: ``inner`` (default: a new ``HTTPTransport``) with a per-attempt deadline.

    Parameters
    ----------
    timeout_s : float
        The most seconds one attempt (connect, send, the whole answer) may take.
    http : module, optional
        The httpx package in use (default: the openai SDK's, :func:`sdk_http_module`).
    inner : transport, optional
    """

    def __init__(self, timeout_s: float, *, http: ModuleType | None = None, inner: Any = None) -> None:
        self.timeout_s = float(timeout_s)
        self._http = http if http is not None else sdk_http_module()
        self._inner = inner if inner is not None else self._http.HTTPTransport()

    def __enter__(self) -> DeadlineTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def handle_request(self, request: Any) -> Any:
        done = threading.Event()
        abandoned = threading.Event()
        box: dict[str, Any] = {}

        def attempt() -> None:
            try:
                response = self._inner.handle_request(request)
                try:
                    chunks = []
                    for chunk in response.stream:
                        if abandoned.is_set():
                            return
                        chunks.append(chunk)
                    box["answer"] = (response.status_code, response.headers, b"".join(chunks), response.extensions)
                finally:
                    response.close()
            except BaseException as error:  # handed to the waiting thread
                box["error"] = error
            finally:
                done.set()

        threading.Thread(target=attempt, name="llm-http-attempt", daemon=True).start()
        if not done.wait(self.timeout_s):
            abandoned.set()
            raise self._http.ReadTimeout(f"no complete answer within {self.timeout_s:g} s", request=request)
        if "error" in box:
            raise box["error"]
        status, headers, body, extensions = box["answer"]
        # The raw (still encoded) bytes with the original headers: httpx decodes them as usual.
        http = self._http
        return http.Response(
            status, headers=headers, stream=http.ByteStream(body), request=request, extensions=extensions
        )

    def close(self) -> None:
        self._inner.close()
