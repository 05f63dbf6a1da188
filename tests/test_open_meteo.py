"""The Open-Meteo archive client, against a local server on 127.0.0.1 (never the public API)."""

from __future__ import annotations

import json
import socket

import httpx
import pytest
from typer.testing import CliRunner

from openmeteo_server import ArchiveServer
from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.data.cities import PAPER_CITIES
from solarchain_eval.data.open_meteo import fetch_city, fetch_weather, parse_archive_response
from solarchain_eval.data.published import PAPER_DATASET_SHA256
from solarchain_eval.data.weather import WeatherError

CENTRES = {c.name: (c.latitude, c.longitude) for c in PAPER_CITIES}


@pytest.fixture(scope="module")
def payload(paper_weather) -> dict:
    return json.loads(paper_weather.read_text())


def _closed_port_url() -> str:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    return f"http://127.0.0.1:{port}/v1/archive"


def test_cli_builds_the_published_dataset_from_the_archive_api(tmp_path, payload, isolated_cache):
    with ArchiveServer(payload, CENTRES) as server:
        result = CliRunner().invoke(
            app,
            ["data", "build", "--out", str(tmp_path / "ds"), "--weather", "open-meteo", "--open-meteo-url", server.url],
        )
    assert result.exit_code == 0, result.output
    assert "byte-identical to the paper's published dataset" in result.output
    for name, digest in PAPER_DATASET_SHA256.items():
        assert sha256_file(tmp_path / "ds" / name) == digest
    # One request per city, for the paper's window, variables and time zone.
    assert len(server.requests) == 5
    assert {r["start_date"] for r in server.requests} == {"2026-04-01"}
    assert {r["end_date"] for r in server.requests} == {"2026-04-30"}
    assert {r["hourly"] for r in server.requests} == {"temperature_2m,shortwave_radiation"}
    assert {r["timezone"] for r in server.requests} == {"Asia/Shanghai"}
    # The payload is cached in the paper's layout and reused without a server.
    cached = list((isolated_cache / "weather").glob("open_meteo_weather_2026-04-01_2026-05-01_*.json"))
    assert len(cached) == 1
    entry = json.loads(cached[0].read_text())["Beijing"]
    assert entry["time"] == payload["Beijing"]["time"] and entry["latitude"] == payload["Beijing"]["latitude"]
    again = CliRunner().invoke(
        app,
        [
            "data",
            "build",
            "--out",
            str(tmp_path / "ds2"),
            "--weather",
            "open-meteo",
            "--open-meteo-url",
            _closed_port_url(),
        ],
    )
    assert again.exit_code == 0, again.output
    assert sha256_file(tmp_path / "ds2" / "p2p_trades.csv") == PAPER_DATASET_SHA256["p2p_trades.csv"]


def test_transient_errors_are_retried(payload):
    slept: list[float] = []
    with ArchiveServer(payload, CENTRES, fail_first=2) as server, httpx.Client() as client:
        weather = fetch_city(
            client,
            server.url,
            PAPER_CITIES[1],
            "2026-04-01",
            "2026-05-01",
            "Asia/Shanghai",
            retries=3,
            sleep=slept.append,
        )
    assert len(server.requests) == 3
    assert slept == [1.0, 2.0]  # exponential back-off
    assert weather.temperature_2m_C == tuple(payload["Shanghai"]["temperature_2m_C"])


def test_retries_exhausted_gives_a_clear_error(payload):
    with (
        ArchiveServer(payload, CENTRES, fail_first=10) as server,
        httpx.Client() as client,
        pytest.raises(WeatherError, match=r"Beijing.*after 3 attempts \(HTTP 503\)"),
    ):
        fetch_city(
            client,
            server.url,
            PAPER_CITIES[0],
            "2026-04-01",
            "2026-05-01",
            "Asia/Shanghai",
            retries=2,
            sleep=lambda s: None,
        )


def test_offline_is_a_clear_error_and_the_cli_exits_2(tmp_path):
    with pytest.raises(WeatherError, match="Offline\\? Use --weather-cache FILE"):
        fetch_weather(PAPER_CITIES[:1], "2026-04-01", "2026-05-01", "Asia/Shanghai", url=_closed_port_url(), retries=0)
    result = CliRunner().invoke(
        app,
        [
            "data",
            "build",
            "--out",
            str(tmp_path / "x"),
            "--weather",
            "open-meteo",
            "--open-meteo-url",
            _closed_port_url(),
            "--retries",
            "0",
            "--city",
            "Wuhan:30.5928:114.3055",
        ],
    )
    assert result.exit_code == 2
    assert "could not get weather for Wuhan" in result.output
    assert not (tmp_path / "x").exists()


def test_missing_values_in_a_response_name_the_city_field_and_time(payload):
    response = ArchiveServer(payload, CENTRES).respond(
        {
            "latitude": str(PAPER_CITIES[2].latitude),
            "longitude": str(PAPER_CITIES[2].longitude),
            "timezone": "Asia/Shanghai",
        }
    )
    response["hourly"]["shortwave_radiation"][30] = None
    with pytest.raises(WeatherError, match=r"Chengdu: 'hourly.shortwave_radiation'\[30\] \(2026-04-02T06:00\) is None"):
        parse_archive_response(response, PAPER_CITIES[2], "Asia/Shanghai")
