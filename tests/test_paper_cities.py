"""The held-out family paper-cities: the paper's market in other months, built from a scripted
Open-Meteo archive on 127.0.0.1 (deterministic synthetic hours), cached, refused months, the
split and suite, and a suite evaluation whose dataset is built on first use through the server."""

from __future__ import annotations

import datetime as dt
import json
import math
import socket
from pathlib import Path

import pytest
from typer.testing import CliRunner

import solarchain_eval
from openmeteo_server import ArchiveServer
from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.data.cities import DEFAULT_SEED, PAPER_CITIES
from solarchain_eval.data.files import DATASET_FILES, MANIFEST_FILE, NODES_FILE
from solarchain_eval.data.paper_cities import (
    PAPER_CITIES_FAMILY,
    build_paper_cities,
    paper_cities_dataset,
    paper_cities_design,
)
from solarchain_eval.data.published import PAPER_DATASET_SHA256, PAPER_WEATHER_SHA256, read_paper_weather
from solarchain_eval.data.sources import Weather, open_meteo_cache_path
from solarchain_eval.data.splits import get_split
from solarchain_eval.data.weather import CityWeather, WeatherError, write_weather_cache
from solarchain_eval.tasks.suites import Suite, get_suite, register_suite, unregister_suite

runner = CliRunner()
CENTRES = {c.name: (c.latitude, c.longitude) for c in PAPER_CITIES}
DEFAULT_MONTHS = ["2026-05", "2026-06", "2026-07", "2026-08", "2026-09", "2026-10"]


def _hours(start: str, last_day: str) -> list[str]:
    first = dt.datetime.fromisoformat(start)
    count = ((dt.date.fromisoformat(last_day) - first.date()).days + 1) * 24
    return [(first + dt.timedelta(hours=h)).strftime("%Y-%m-%dT%H:%M") for h in range(count)]


def synthetic_city(city: int, times: list[str]) -> dict:
    """A city's hours: a daytime sine bell dimmed by a day- and city-dependent cloud factor."""
    radiation, temperature = [], []
    for stamp in times:
        moment = dt.datetime.fromisoformat(stamp)
        day, hour = moment.timetuple().tm_yday, moment.hour
        clouds = 1.0 - 0.15 * ((3 * day + city) % 5)
        radiation.append(round(max(0.0, 850.0 * math.sin(math.pi * (hour - 6) / 12)) * clouds, 1))
        temperature.append(round(18.0 + 2 * city + 6.0 * math.sin(math.pi * (hour - 9) / 12), 1))
    return {"time": times, "temperature_2m_C": temperature, "shortwave_radiation_Wm2": radiation}


class SyntheticArchive(ArchiveServer):
    """Answers any month with :func:`synthetic_city` hours for the dates asked."""

    def __init__(self) -> None:
        super().__init__({}, CENTRES)

    def respond(self, query: dict[str, str]) -> dict:
        index = next(i for i, (lat, _lon) in enumerate(CENTRES.values()) if abs(lat - float(query["latitude"])) < 1e-9)
        name = list(CENTRES)[index]
        hours = synthetic_city(index, _hours(query["start_date"], query["end_date"]))
        self.payload[name] = {"latitude": CENTRES[name][0], "longitude": CENTRES[name][1], **hours}
        return super().respond(query)


def _closed_port_url() -> str:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    return f"http://127.0.0.1:{port}/v1/archive"


def _hashes(folder: Path) -> dict[str, str]:
    return {name: sha256_file(folder / name) for name in DATASET_FILES}


@pytest.fixture()
def cache(tmp_path, monkeypatch) -> Path:
    """A cache of this test's own (no payload or dataset of another test is reused)."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("SOLARCHAIN_CACHE_DIR", str(folder))
    return folder


def test_the_design_is_the_papers_but_for_month_and_weather():
    may = paper_cities_dataset("2026-05")
    assert (may.name, may.start, may.end) == ("paper-cities-2026-05", "2026-05-01", "2026-06-01")
    assert (may.seed, may.nodes_per_city, may.timezone) == (DEFAULT_SEED, 10, "Asia/Shanghai")
    december = paper_cities_dataset("2025-12")
    assert (december.start, december.end) == ("2025-12-01", "2026-01-01")
    assert [e.dataset for e in get_split("paper-cities").entries] == [f"paper-cities-{m}" for m in DEFAULT_MONTHS]
    for bad in ("2026-13", "2026-4", "May 2026", "1939-12"):
        with pytest.raises(WeatherError, match="paper-cities: "):
            paper_cities_dataset(bad)
    with pytest.raises(WeatherError, match="2026-04 is the paper's month \\(the train split\\)"):
        paper_cities_dataset("2026-04")


def test_april_from_the_papers_payload_is_the_papers_dataset(tmp_path):
    """The family's design for the paper's month, fed the paper's payload, gives the published CSVs:
    so a paper-cities month differs from the paper's dataset by its weather and month alone."""
    weather = Weather(read_paper_weather(PAPER_CITIES), "the paper's payload", PAPER_WEATHER_SHA256)
    built = build_paper_cities(paper_cities_design("2026-04"), weather, tmp_path / "april")
    assert _hashes(built.out_dir) == PAPER_DATASET_SHA256
    assert built.manifest["family"] == PAPER_CITIES_FAMILY


def test_build_family_fetches_once_and_rebuilds_byte_identically_from_the_cache(tmp_path, cache):
    args = ["data", "build-family", "paper-cities", "--month", "2026-06", "--month", "2026-05"]
    with SyntheticArchive() as server:
        done = runner.invoke(app, [*args, "--out", str(tmp_path / "a"), "--open-meteo-url", server.url])
    assert done.exit_code == 0, done.output
    assert "Open-Meteo.com (CC BY 4.0)" in done.output and "not pinned" in done.output
    assert sorted((r["start_date"], r["end_date"]) for r in server.requests) == sorted(
        [("2026-05-01", "2026-05-31")] * 5 + [("2026-06-01", "2026-06-30")] * 5
    )
    assert {r["timezone"] for r in server.requests} == {"Asia/Shanghai"}
    first = {}
    for month, hours in (("2026-05", 744), ("2026-06", 720)):
        folder = tmp_path / "a" / f"paper-cities-{month}"
        manifest = json.loads((folder / MANIFEST_FILE).read_text())
        payload = open_meteo_cache_path(PAPER_CITIES, f"{month}-01", manifest["end"])
        assert manifest["family"] == "paper-cities" and manifest["hours"] == hours
        assert manifest["weather_source"] == (
            "held-out family paper-cities (online, cached): Open-Meteo Historical Weather API"
        )
        assert manifest["weather_sha256"] == sha256_file(payload)
        assert (manifest["weather_attribution"]["licence"], manifest["seed"]) == ("CC BY 4.0", DEFAULT_SEED)
        assert [c["name"] for c in manifest["cities"]] == [c.name for c in PAPER_CITIES]
        first[month] = _hashes(folder)
        # the paper's seed draws the paper's fleet first: the nodes file is the published one
        assert first[month][NODES_FILE] == PAPER_DATASET_SHA256[NODES_FILE]
    assert first["2026-05"] != first["2026-06"]
    # From the cache, with no server: the same bytes.
    again = runner.invoke(
        app, [*args[:4], "2026-05", "--out", str(tmp_path / "b"), "--open-meteo-url", _closed_port_url()]
    )
    assert again.exit_code == 0, again.output
    assert _hashes(tmp_path / "b" / "paper-cities-2026-05") == first["2026-05"]
    assert len(server.requests) == 10


def test_refused_months_write_nothing(tmp_path, cache):
    out = tmp_path / "out"
    for month, message in (
        ("2026-04", "paper-cities: 2026-04 is the paper's month (the train split), not a held-out one"),
        ("2026/05", "paper-cities: a month is YYYY-MM (e.g. 2026-05), got '2026/05'"),
    ):
        done = runner.invoke(app, ["data", "build-family", "paper-cities", "--month", month, "--out", str(out)])
        assert done.exit_code == 2 and message in done.output, done.output
        assert len(done.output.strip().splitlines()) == 1
    tmy = runner.invoke(app, ["data", "build-family", "tmy-3sites", "--month", "13", "--out", str(out)])
    assert tmy.exit_code == 2 and "tmy-3sites: month must be 1..12, got 13" in tmy.output
    assert not out.exists() and not cache.exists()


def test_an_unreachable_archive_is_one_line_and_nothing_is_written(tmp_path, cache):
    url = _closed_port_url()
    out = tmp_path / "out"
    args = ["data", "build-family", "paper-cities", "--out", str(out), "--open-meteo-url", url, "--retries", "0"]
    done = runner.invoke(app, [*args, "--month", "2026-07"])
    assert done.exit_code == 2
    assert len(done.output.strip().splitlines()) == 1, done.output
    assert f"from {url} after 1 attempts" in done.output
    assert "paper-cities is built online" in done.output
    assert not out.exists() and not (cache / "weather").exists()
    # A month whose payload is cached builds; the next one cannot: the built one goes too.
    may = paper_cities_dataset("2026-05")
    times = _hours("2026-05-01T00:00", "2026-05-31")
    write_weather_cache(
        open_meteo_cache_path(PAPER_CITIES, may.start, may.end),
        {
            c.name: CityWeather(
                "Open-Meteo Historical Weather API",
                c.latitude,
                c.longitude,
                "Asia/Shanghai",
                tuple(times),
                tuple(synthetic_city(i, times)["temperature_2m_C"]),
                tuple(synthetic_city(i, times)["shortwave_radiation_Wm2"]),
            )
            for i, c in enumerate(PAPER_CITIES)
        },
    )
    both = runner.invoke(app, [*args, "--month", "2026-05", "--month", "2026-06"])
    assert both.exit_code == 2 and "could not get weather for Beijing" in both.output, both.output
    assert not out.exists()


def test_the_split_and_the_suite(cache):
    suite = get_suite("paper-cities")
    assert [(e.name, e.split, e.task) for e in suite.entries] == [
        (f"paper-cities-{m}", "paper-cities", "solar") for m in DEFAULT_MONTHS
    ]
    assert get_split("paper-cities").role == "test" and suite.splits == ("paper-cities",)
    # built online: bench-suite's default (offline) build leaves it out
    assert suite.online and not any(get_suite(n).online for n in ("heldout", "train", "paper-early", "paper-late"))
    listed = runner.invoke(app, ["data", "splits"])
    assert listed.exit_code == 0, listed.output
    row = next(line for line in listed.output.splitlines() if line.startswith("│ paper-cities"))
    assert "paper-cities-2026-05" in row and row.count("paper-cities") >= 3  # split, datasets and suite


def test_a_suite_entry_is_built_through_the_archive_on_first_use(tmp_path, cache, monkeypatch):
    """The real suite's first entry: built online into the cache when the suite runs, offline afterwards."""
    entry = get_suite("paper-cities").entries[0]
    one = Suite("paper-cities-first", "the first month of paper-cities", (entry,))
    register_suite(one)
    try:
        with SyntheticArchive() as server:
            monkeypatch.setenv("SOLARCHAIN_OPEN_METEO_URL", server.url)
            result = solarchain_eval.evaluate(
                "static", suite=one.name, seeds=(20260511,), episodes=2, out=tmp_path / "s"
            )
    finally:
        unregister_suite(one.name)
    assert len(server.requests) == 5
    built = cache / "datasets" / "paper-cities-2026-05"
    assert json.loads((built / MANIFEST_FILE).read_text())["family"] == "paper-cities"
    # the dataset's own sha256s are in the entry's run protocol
    assert result.runs[entry.name].protocol["dataset_sha256"] == _hashes(built)
    monkeypatch.setenv("SOLARCHAIN_OPEN_METEO_URL", _closed_port_url())
    assert entry.data_dir() == built  # from the cache, offline
