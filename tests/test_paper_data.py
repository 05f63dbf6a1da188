"""The paper's data in the package: the packaged weather payload, its checks, and the default dataset built from it."""

from __future__ import annotations

import hashlib
import json
import lzma
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

import solarchain_eval.data.published as published
from conftest import PAPER_WEATHER, PUBLISHED
from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.data.cities import PAPER_CITIES, City
from solarchain_eval.data.default import DEFAULT_DATASET_NAME, default_dataset_dir
from solarchain_eval.data.files import DATASET_FILES, MANIFEST_FILE
from solarchain_eval.data.published import (
    PAPER_DATASET_SHA256,
    PAPER_WEATHER_SHA256,
    PackagedWeatherError,
    PublishedMismatchError,
    read_paper_weather,
    read_paper_weather_bytes,
)
from solarchain_eval.data.sources import WeatherSource, choose_weather
from solarchain_eval.data.synthetic import SYNTHETIC_SOURCE
from solarchain_eval.data.weather import WeatherError

#: The paper's release checksums, written out here so the test does not trust the packaged file alone.
RELEASE_SHA256 = {
    "market_liquidity.csv": "ddf7b4b8c34b11a898ed5a32661fce5777f1d17d0a49f1da29b85347e53cbced",
    "p2p_trades.csv": "4bcd0cff533f99e3787f70d87ecc5e0a268c668cd47120c7936f87ab3c2c91ee",
    "spatiotemporal_generation.csv": "caa0d95656e618e7d54c98bfed507128a94edac454b8b964ac06f3541f9b190e",
    "urban_energy_nodes.csv": "6ccea1564cb709df7b8e4bb784e72afc5ef0f0014d7ff96f55ba1701f6d5bcd0",
}
RELEASE_WEATHER_SHA256 = "9c373f057ade383f2adf21941c1bbefc13bce38f9aa7641874052e9fec510842"
DATASET_LINE = "(the paper's published dataset, rebuilt from the packaged weather; sha256s checked)"


def _damaged_copy(tmp_path: Path, *, flip_at: int | None = None, json_edit: bytes | None = None) -> Path:
    """A copy of the packaged payload with one compressed byte flipped, or valid xz of edited JSON."""
    path = tmp_path / f"{PAPER_WEATHER}.xz"
    if json_edit is not None:
        raw = read_paper_weather_bytes()
        edited = raw.replace(b"116.35983", json_edit, 1)
        assert edited != raw and len(edited) == len(raw)
        path.write_bytes(lzma.compress(edited, format=lzma.FORMAT_XZ))
    else:
        data = bytearray(published.PAPER_WEATHER_RESOURCE.read_bytes())
        data[flip_at] ^= 0x01
        path.write_bytes(bytes(data))
    return path


def test_packaged_payload_is_small_and_checksummed():
    compressed = published.PAPER_WEATHER_RESOURCE.read_bytes()
    assert compressed[:6] == b"\xfd7zXZ\x00" and len(compressed) < 12_000
    raw = read_paper_weather_bytes()
    assert hashlib.sha256(raw).hexdigest() == PAPER_WEATHER_SHA256 == RELEASE_WEATHER_SHA256
    assert len(raw) == 180_881
    assert PAPER_DATASET_SHA256 == RELEASE_SHA256


def test_packaged_payload_and_checksums_are_the_releases(shared_data):
    assert read_paper_weather_bytes() == (shared_data / PAPER_WEATHER).read_bytes()
    assert sha256_file(shared_data / PAPER_WEATHER) == PAPER_WEATHER_SHA256
    release_lines = set((shared_data / "SHA256SUMS").read_text().splitlines())
    packaged_lines = published.CHECKSUMS_RESOURCE.read_text().splitlines()
    assert len(packaged_lines) == 5 and set(packaged_lines) <= release_lines


def test_default_dataset_is_the_published_dataset(published_dir, isolated_cache):
    assert published_dir == isolated_cache / "datasets" / DEFAULT_DATASET_NAME
    assert {name: sha256_file(published_dir / name) for name in DATASET_FILES} == RELEASE_SHA256
    manifest = json.loads((published_dir / MANIFEST_FILE).read_text())
    assert manifest["weather_sha256"] == RELEASE_WEATHER_SHA256
    assert "the paper's payload" in manifest["weather_source"]
    attribution = manifest["weather_attribution"]
    assert attribution["attribution"] == "Weather data by Open-Meteo.com"
    assert attribution["licence"] == "CC BY 4.0"
    assert attribution["licence_url"] == "https://creativecommons.org/licenses/by/4.0/"
    assert "xz-compressed" in attribution["changes"]


def test_default_dataset_equals_the_published_csvs_byte_for_byte(published_dir, shared_data):
    for name in DATASET_FILES:
        assert (published_dir / name).read_bytes() == (shared_data / PUBLISHED / name).read_bytes(), name


def test_flipped_byte_in_the_packaged_payload_is_a_clear_error(tmp_path, monkeypatch):
    damaged = _damaged_copy(tmp_path, flip_at=4_000)
    monkeypatch.setattr(published, "PAPER_WEATHER_RESOURCE", damaged)
    with pytest.raises(
        PackagedWeatherError, match=rf"{re.escape(str(damaged))} is damaged .*reinstall solarchain-eval"
    ):
        read_paper_weather_bytes()


def test_payload_with_other_json_fails_its_sha256_check(tmp_path, monkeypatch):
    damaged = _damaged_copy(tmp_path, json_edit=b"116.35984")
    monkeypatch.setattr(published, "PAPER_WEATHER_RESOURCE", damaged)
    with pytest.raises(
        PackagedWeatherError, match=f"its JSON has sha256 [0-9a-f]{{64}}, not the paper's {PAPER_WEATHER_SHA256}"
    ):
        read_paper_weather(PAPER_CITIES)


def test_missing_payload_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setattr(published, "PAPER_WEATHER_RESOURCE", tmp_path / "gone.json.xz")
    with pytest.raises(PackagedWeatherError, match="cannot be read .*reinstall solarchain-eval"):
        read_paper_weather_bytes()


def test_damaged_payload_stops_run_and_build_with_one_line_and_nothing_written(tmp_path, monkeypatch):
    monkeypatch.setattr(published, "PAPER_WEATHER_RESOURCE", _damaged_copy(tmp_path, json_edit=b"116.35984"))
    monkeypatch.setenv("SOLARCHAIN_CACHE_DIR", str(tmp_path / "cache"))
    run = CliRunner().invoke(app, ["run", "--episodes", "1", "--seeds", "20260511", "--out", str(tmp_path / "run")])
    assert run.exit_code == 2
    assert run.output.startswith("error: the paper's weather payload ") and "is damaged" in run.output
    assert not (tmp_path / "cache" / "datasets").exists() and not (tmp_path / "run").exists()
    build = CliRunner().invoke(app, ["data", "build", "--out", str(tmp_path / "ds")])
    assert build.exit_code == 2 and "is damaged" in build.output
    assert not (tmp_path / "ds").exists()


def test_a_rebuild_differing_from_the_published_files_is_refused_and_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("SOLARCHAIN_CACHE_DIR", str(tmp_path))
    monkeypatch.setitem(published.PAPER_DATASET_SHA256, "p2p_trades.csv", "0" * 64)
    with pytest.raises(
        PublishedMismatchError, match=f"p2p_trades.csv has sha256 {RELEASE_SHA256['p2p_trades.csv']}"
    ) as caught:
        default_dataset_dir()
    assert list(caught.value.mismatched) == ["p2p_trades.csv"]
    assert list((tmp_path / "datasets").iterdir()) == []  # neither the dataset nor its staging folder


def test_run_on_a_fresh_cache_builds_and_names_the_papers_dataset(tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    old_synthetic = cache / "datasets" / "default-synthetic-v1-20260511"
    old_synthetic.mkdir(parents=True)
    (old_synthetic / MANIFEST_FILE).write_text("{}")  # a previous version's default must not be taken for it
    monkeypatch.setenv("SOLARCHAIN_CACHE_DIR", str(cache))
    result = CliRunner().invoke(app, ["run", "--episodes", "1", "--seeds", "20260511", "--out", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    target = cache / "datasets" / DEFAULT_DATASET_NAME
    assert f"dataset: {target} {DATASET_LINE}" in " ".join(result.output.split())
    assert {name: sha256_file(target / name) for name in DATASET_FILES} == RELEASE_SHA256
    metadata = json.loads((tmp_path / "run" / "run_metadata.json").read_text())
    assert json.dumps(metadata).count(RELEASE_SHA256["spatiotemporal_generation.csv"]) >= 1


def test_data_build_without_a_weather_option_builds_the_papers_dataset(tmp_path):
    result = CliRunner().invoke(app, ["data", "build", "--out", str(tmp_path / "ds")])
    assert result.exit_code == 0, result.output
    assert "byte-identical to the paper's published dataset" in result.output
    assert {name: sha256_file(tmp_path / "ds" / name) for name in DATASET_FILES} == RELEASE_SHA256
    manifest = json.loads((tmp_path / "ds" / MANIFEST_FILE).read_text())
    assert manifest["weather_attribution"]["attribution"] == "Weather data by Open-Meteo.com"


def test_weather_paper_refuses_builds_it_does_not_cover(tmp_path):
    result = CliRunner().invoke(
        app, ["data", "build", "--out", str(tmp_path / "ds"), "--weather", "paper", "--city", "Wuhan:30.5928:114.3055"]
    )
    assert result.exit_code == 2 and "the paper's weather covers only its five cities" in result.output
    assert not (tmp_path / "ds").exists()


@pytest.mark.parametrize(
    ("cities", "start", "end", "timezone", "expected"),
    [
        (PAPER_CITIES, "2026-04-01", "2026-05-01", "Asia/Shanghai", "paper"),
        (PAPER_CITIES[1:3], "2026-04-10", "2026-04-12", "Asia/Shanghai", "paper"),
        (PAPER_CITIES, "2026-03-31", "2026-04-02", "Asia/Shanghai", "synthetic"),
        (PAPER_CITIES, "2026-04-01", "2026-05-02", "Asia/Shanghai", "synthetic"),
        (PAPER_CITIES, "2026-04-01", "2026-04-03", "UTC", "synthetic"),
        ((City("Beijing", 40.0, 116.4074),), "2026-04-01", "2026-04-03", "Asia/Shanghai", "synthetic"),
    ],
)
def test_default_weather_is_the_papers_exactly_where_it_covers_the_build(cities, start, end, timezone, expected):
    notices: list[str] = []
    chosen = choose_weather(cities, start, end, seed=1, timezone=timezone, notify=notices.append)
    if expected == "paper":
        assert chosen.sha256 == RELEASE_WEATHER_SHA256 and not notices
        assert chosen.payload == read_paper_weather(cities)
    else:
        assert chosen.source == SYNTHETIC_SOURCE and chosen.sha256 is None
        assert notices == [
            "weather: synthetic (the paper's packaged weather covers its five cities, Asia/Shanghai, April 2026)"
        ]


def test_explicit_paper_weather_for_other_dates_is_an_error():
    with pytest.raises(WeatherError, match="dates from 2026-04-01 to 2026-05-01"):
        choose_weather(
            PAPER_CITIES, "2026-05-01", "2026-05-03", seed=1, timezone="Asia/Shanghai", source=WeatherSource.paper
        )
