"""A scripted agent server for the HTTP-agent tests (standard library, in a thread).

The path picks the behaviour: ``/ok`` answers :attr:`ScriptedAgentServer.action`, ``/range`` an
action outside [0, 1], ``/length`` two numbers, ``/notjson`` text, ``/flaky`` HTTP 500 on its
first request and then ``/ok``'s answer, ``/down`` always 500, ``/slow`` sleeps past the
client's timeout, ``/nan`` a NaN component, ``/discrete/<json>`` the given JSON action; any
other path is a 404. Every request is recorded with its path, client address (one per TCP
connection) and JSON body.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import unquote


@dataclass
class Seen:
    path: str
    client: tuple[str, int]
    body: dict | None


@dataclass
class ScriptedAgentServer:
    action: list[float] = field(default_factory=lambda: [0.5, 0.5, 0.5])
    slow_s: float = 0.6
    requests: list[Seen] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.lock = threading.Lock()
        owner = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"
            disable_nagle_algorithm = True

            def do_POST(self) -> None:
                raw = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                path = self.path.partition("?")[0]
                with owner.lock:
                    owner.requests.append(Seen(path, self.client_address, json.loads(raw) if raw else None))
                    count = sum(1 for r in owner.requests if r.path == path)
                status, text = owner.answer(path, count)
                data = text.encode()
                self.send_response(status)
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def log_message(self, format: str, *args: object) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.handle_error = lambda request, address: None  # the client gave up on /slow
        self.thread = threading.Thread(target=self.server.serve_forever, args=(0.05,), daemon=True)
        self.thread.start()

    def url(self, path: str) -> str:
        return f"http://127.0.0.1:{self.server.server_address[1]}{path}"

    def answer(self, path: str, count: int) -> tuple[int, str]:
        ok = json.dumps({"action": self.action})
        if path == "/ok" or (path == "/flaky" and count > 1):
            return 200, ok
        if path in ("/flaky", "/down"):
            return 500, "internal error\nwith a second line"
        if path == "/slow":
            time.sleep(self.slow_s)
            return 200, ok
        if path.startswith("/discrete/"):
            return 200, json.dumps({"action": json.loads(unquote(path.removeprefix("/discrete/")))})
        fixed = {"/range": '{"action": [0.25, 1.7, 0.0]}', "/length": '{"action": [0.1, 0.2]}',
                 "/notjson": "<html>oops</html>", "/nan": '{"action": [0.1, NaN, 0.2]}', "/noaction": '{"act": 1}'}  # fmt: skip
        if path in fixed:
            return 200, fixed[path]
        return 404, "no such agent"

    def seen(self, path: str) -> list[Seen]:
        with self.lock:
            return [r for r in self.requests if r.path == path]

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
