"""A local HTTP server speaking the Open-Meteo archive API's wire format (tests only)."""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs, urlparse


class ArchiveServer:
    """Serves a cached weather payload (paper layout) as archive API responses.

    ``fail_first`` requests are answered with HTTP 503 first; every request's query is kept.
    """

    def __init__(self, payload: dict, centres: dict[str, tuple[float, float]], fail_first: int = 0):
        self.payload, self.centres, self.fail_first = payload, centres, fail_first
        self.requests: list[dict[str, str]] = []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args) -> None:  # keep test output quiet
                return None

            def do_GET(self) -> None:
                query = {k: v[0] for k, v in parse_qs(urlparse(self.path).query).items()}
                outer.requests.append(query)
                if len(outer.requests) <= outer.fail_first:
                    self.send_response(503)
                    self.end_headers()
                    return
                body = json.dumps(outer.respond(query)).encode()
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def respond(self, query: dict[str, str]) -> dict:
        lat, lon = float(query["latitude"]), float(query["longitude"])
        city = next(
            name for name, (clat, clon) in self.centres.items() if abs(clat - lat) < 1e-9 and abs(clon - lon) < 1e-9
        )
        data = self.payload[city]
        return {
            "latitude": data["latitude"],
            "longitude": data["longitude"],
            "generationtime_ms": 0.2,
            "utc_offset_seconds": 28800,
            "timezone": query["timezone"],
            "timezone_abbreviation": "GMT+8",
            "elevation": 44.0,
            "hourly_units": {"time": "iso8601", "temperature_2m": "°C", "shortwave_radiation": "W/m²"},
            "hourly": {
                "time": data["time"],
                "temperature_2m": data["temperature_2m_C"],
                "shortwave_radiation": data["shortwave_radiation_Wm2"],
            },
        }

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server.server_address[1]}/v1/archive"

    def __enter__(self) -> ArchiveServer:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.server.shutdown()
        self.server.server_close()
