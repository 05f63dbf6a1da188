"""Open a local HTML file in headless Chromium and report what a reader's browser would see.

Drives Debian's ``chromium`` over the DevTools protocol (one websocket, via the small
``websocket-client`` package): console errors, uncaught exceptions, failed loads, every
image's natural size, every network request, and an optional screenshot. Only file: and data:
URLs are opened; the debugging port listens on 127.0.0.1 and is chosen by Chromium.
"""

from __future__ import annotations

import base64
import contextlib
import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--hide-scrollbars",
    "--remote-debugging-address=127.0.0.1",
    "--remote-debugging-port=0",
)


def find_chromium() -> str | None:
    """Path of a Chromium binary on PATH, or None."""
    for name in CHROMIUM_NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


@dataclass
class PageReport:
    """What loading the page produced."""

    console_errors: list[str] = field(default_factory=list)
    images: list[dict[str, Any]] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)
    title: str = ""
    #: One entry per requested action: an ``eval``'s value, None for a ``click``.
    results: list[Any] = field(default_factory=list)


class _DevTools:
    def __init__(self, ws_url: str, timeout_s: float):
        import websocket  # websocket-client

        self.socket = websocket.create_connection(ws_url, timeout=timeout_s, suppress_origin=True)
        self.next_id = 0
        self.events: list[dict[str, Any]] = []

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        self.next_id += 1
        self.socket.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            message = json.loads(self.socket.recv())
            if message.get("id") == self.next_id:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message.get("result", {})
            self.events.append(message)

    def wait_for(self, method: str, deadline: float) -> None:
        if any(e.get("method") == method for e in self.events):
            return
        while time.monotonic() < deadline:
            message = json.loads(self.socket.recv())
            self.events.append(message)
            if message.get("method") == method:
                return
        raise TimeoutError(f"no {method} before the deadline")

    def close(self) -> None:
        self.socket.close()


def _devtools_port(profile: Path, process: subprocess.Popen, deadline: float) -> int:
    marker = profile / "DevToolsActivePort"
    while time.monotonic() < deadline:
        if marker.is_file():
            lines = marker.read_text().splitlines()
            if lines and lines[0].strip().isdigit():
                return int(lines[0])
        if process.poll() is not None:
            raise RuntimeError(f"chromium exited with status {process.returncode} before opening DevTools")
        time.sleep(0.05)
    raise TimeoutError("chromium did not open its DevTools port in time")


def _page_socket(port: int) -> str:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as response:
        targets = json.load(response)
    pages = [t for t in targets if t.get("type") == "page"]
    if not pages:
        raise RuntimeError("chromium has no page target")
    return pages[0]["webSocketDebuggerUrl"]


def _errors(events: list[dict[str, Any]]) -> list[str]:
    errors = []
    for event in events:
        method, params = event.get("method"), event.get("params", {})
        if method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
            errors.append(
                "console: " + " ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", []))
            )
        elif method == "Runtime.exceptionThrown":
            errors.append("exception: " + params.get("exceptionDetails", {}).get("text", ""))
        elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
            entry = params["entry"]
            errors.append(f"log: {entry.get('text', '')} {entry.get('url', '')}".strip())
        elif method == "Network.loadingFailed":
            errors.append(f"load failed: {params.get('errorText', '')}")
    return errors


CENTRE_JS = (
    "(function () {{ var e = document.querySelector({selector}); if (!e) return null; "
    "e.scrollIntoView({{block: 'center'}}); var r = e.getBoundingClientRect(); "
    "return JSON.stringify([r.left + r.width / 2, r.top + r.height / 2]); }})()"
)


def _run_action(tools: _DevTools, kind: str, argument: str) -> Any:
    """``("eval", expression)``: the expression's value; ``("click", css selector)``: a left mouse
    click at the element's centre, dispatched as real input events (None)."""
    if kind == "eval":
        result = tools.call("Runtime.evaluate", expression=argument, returnByValue=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{argument}: {result['exceptionDetails'].get('text', '')}")
        return result["result"].get("value")
    if kind != "click":
        raise ValueError(f"unknown page action {kind!r} (eval or click)")
    found = tools.call(
        "Runtime.evaluate", expression=CENTRE_JS.format(selector=json.dumps(argument)), returnByValue=True
    )
    if found["result"].get("value") is None:
        raise RuntimeError(f"no element matches {argument!r}")
    x, y = json.loads(found["result"]["value"])
    for event in ("mouseMoved", "mousePressed", "mouseReleased"):
        tools.call("Input.dispatchMouseEvent", type=event, x=x, y=y, button="left", clickCount=1)
    return None


IMAGES_JS = (
    "JSON.stringify(Array.from(document.images).map(i => ({alt: i.alt, complete: i.complete, "
    "naturalWidth: i.naturalWidth, naturalHeight: i.naturalHeight, scheme: i.src.split(':')[0]})))"
)


def open_page(
    html_file: Path,
    *,
    screenshots: dict[str, tuple[int, int, int, int]] | None = None,
    width: int = 1280,
    timeout_s: float = 60.0,
    actions: list[tuple[str, str]] | None = None,
) -> tuple[PageReport, dict[str, bytes]]:
    """Load ``html_file`` in a fresh headless Chromium profile and inspect it.

    Parameters
    ----------
    html_file
        The page (opened as a file: URL).
    screenshots
        Optional clips to capture, name -> (x, y, width, height) in CSS pixels of the full page.
    width
        Viewport width in CSS pixels.
    timeout_s
        Limit for start-up and for the page's load event.
    actions
        Run after the load, in order: ``("click", css_selector)`` clicks the element with the
        mouse, ``("eval", js_expression)`` records the expression's value in ``results``.

    Returns
    -------
    (PageReport, PNG bytes per requested clip)
    """
    binary = find_chromium()
    if binary is None:
        raise FileNotFoundError("no chromium binary on PATH")
    profile = Path(tempfile.mkdtemp(prefix="solarchain-chromium-"))
    process = subprocess.Popen(
        [binary, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size={width},900", "about:blank"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    shots: dict[str, bytes] = {}
    try:
        deadline = time.monotonic() + timeout_s
        port = _devtools_port(profile, process, deadline)
        tools = _DevTools(_page_socket(port), timeout_s)
        try:
            for domain in ("Runtime", "Log", "Page", "Network"):
                tools.call(f"{domain}.enable")
            tools.call("Page.navigate", url=Path(html_file).resolve().as_uri())
            tools.wait_for("Page.loadEventFired", time.monotonic() + timeout_s)
            report = PageReport()
            report.results = [_run_action(tools, kind, argument) for kind, argument in actions or ()]
            report.images = json.loads(
                tools.call("Runtime.evaluate", expression=IMAGES_JS, returnByValue=True)["result"]["value"]
            )
            report.title = tools.call("Runtime.evaluate", expression="document.title", returnByValue=True)["result"][
                "value"
            ]
            for name, (x, y, w, h) in (screenshots or {}).items():
                result = tools.call(
                    "Page.captureScreenshot",
                    format="png",
                    captureBeyondViewport=True,
                    clip={"x": x, "y": y, "width": w, "height": h, "scale": 1},
                )
                shots[name] = base64.b64decode(result["data"])
            report.console_errors = _errors(tools.events)
            report.requests = [
                e["params"]["request"]["url"][:80]
                for e in tools.events
                if e.get("method") == "Network.requestWillBeSent"
            ]
            # the browser may close the socket before answering
            with contextlib.suppress(Exception):
                tools.call("Browser.close")
        finally:
            tools.close()
    finally:
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=10)
        shutil.rmtree(profile, ignore_errors=True)
    return report, shots
