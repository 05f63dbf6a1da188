"""Dataset build: byte-identity with the published CSVs, determinism, any cities."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.data.build import DATASET_FILES, MANIFEST_FILE, build_dataset
from solarchain_eval.data.cities import PAPER_CITIES, City
from solarchain_eval.data.published import PAPER_DATASET_SHA256
from solarchain_eval.data.synthetic import synthesize_weather
from solarchain_eval.data.weather import WeatherError, read_weather_cache


def _build(weather, out, cities=PAPER_CITIES, **kw):
    args = dict(
        seed=20260511,
        start="2026-04-01",
        end="2026-05-01",
        nodes_per_city=10,
        timezone="Asia/Shanghai",
        weather_source="test",
    )
    args.update(kw)
    return build_dataset(weather, out, cities=cities, **args)


def test_build_from_cached_paper_weather_is_byte_identical(tmp_path, paper_weather, published_dir):
    weather = read_weather_cache(paper_weather, PAPER_CITIES)
    result = _build(weather, tmp_path)
    for name in DATASET_FILES:
        assert sha256_file(tmp_path / name) == PAPER_DATASET_SHA256[name], name
        assert (tmp_path / name).read_bytes() == (published_dir / name).read_bytes(), name
    manifest = json.loads((tmp_path / MANIFEST_FILE).read_text())
    assert manifest == result.manifest
    assert manifest["files"]["spatiotemporal_generation.csv"]["rows"] == 36_000
    assert manifest["files"]["p2p_trades.csv"]["rows"] == 1_185
    assert manifest["files"]["market_liquidity.csv"]["rows"] == 720
    assert manifest["seed"] == 20260511 and manifest["hours"] == 720
    assert {"numpy", "pandas", "pvlib"} <= set(manifest["package_versions"])


def test_published_checksums_file_agrees_with_embedded_checksums(shared_data):
    sums = (shared_data / "SHA256SUMS").read_text().split("\n")
    listed = {line.split()[1].split("/")[-1]: line.split()[0] for line in sums if "published" in line}
    assert listed == PAPER_DATASET_SHA256


def test_synthetic_build_is_deterministic_and_seed_dependent(tmp_path):
    cities = (City("Wuhan", 30.5928, 114.3055), City("Lhasa", 29.652, 91.1721))
    weather = synthesize_weather(cities, "2026-07-01", "2026-07-04", 11, "Asia/Shanghai")
    again = synthesize_weather(cities, "2026-07-01", "2026-07-04", 11, "Asia/Shanghai")
    assert weather == again
    a = _build(weather, tmp_path / "a", cities=cities, seed=11, start="2026-07-01", end="2026-07-04", nodes_per_city=3)
    b = _build(weather, tmp_path / "b", cities=cities, seed=11, start="2026-07-01", end="2026-07-04", nodes_per_city=3)
    c = _build(weather, tmp_path / "c", cities=cities, seed=12, start="2026-07-01", end="2026-07-04", nodes_per_city=3)
    assert a.manifest["files"] == b.manifest["files"]
    assert a.manifest["files"] != c.manifest["files"]
    nodes = pd.read_csv(tmp_path / "a" / "urban_energy_nodes.csv")
    assert list(nodes["node_id"]) == ["WUH-001", "WUH-002", "WUH-003", "LHA-001", "LHA-002", "LHA-003"]
    generation = pd.read_csv(tmp_path / "a" / "spatiotemporal_generation.csv")
    assert len(generation) == 6 * 72
    assert generation["fdia_detected"].sum() == round(0.05 * 6 * 72)
    # Night hours produce no power; midday hours do (a sanity check of the pvlib geometry).
    noon = generation[generation["hour"] == 12]
    midnight = generation[generation["hour"] == 0]
    assert (midnight["P_max_W"] == 0).all() and (noon["P_max_W"] > 0).all()


def test_synthetic_weather_of_a_city_does_not_depend_on_the_other_cities():
    wuhan = City("Wuhan", 30.5928, 114.3055)
    alone = synthesize_weather([wuhan], "2026-07-01", "2026-07-03", 5, "Asia/Shanghai")["Wuhan"]
    together = synthesize_weather(
        [City("Lhasa", 29.652, 91.1721), wuhan], "2026-07-01", "2026-07-03", 5, "Asia/Shanghai"
    )["Wuhan"]
    assert alone == together
    assert max(alone.shortwave_radiation_Wm2) > 300 and min(alone.shortwave_radiation_Wm2) == 0


def test_weather_not_covering_the_window_is_rejected(tmp_path, paper_weather):
    weather = read_weather_cache(paper_weather, PAPER_CITIES)
    with pytest.raises(WeatherError, match="Beijing.*first gap at 2026-05-01"):
        _build(weather, tmp_path, end="2026-05-03")


def test_data_build_names_the_papers_weather_and_dataset(tmp_path, paper_weather):
    """The CLI says when the weather is the paper's payload (by sha256) and the CSVs the published ones."""
    from typer.testing import CliRunner

    from solarchain_eval.cli import app
    from solarchain_eval.data.published import PAPER_WEATHER_SHA256

    assert sha256_file(paper_weather) == PAPER_WEATHER_SHA256
    paper = CliRunner().invoke(
        app, ["data", "build", "--out", str(tmp_path / "p"), "--weather-cache", str(paper_weather)]
    )
    assert paper.exit_code == 0, paper.output
    assert "the paper's Open-Meteo payload (sha256 matches)" in paper.output
    assert "Weather data by Open-Meteo.com (CC BY 4.0" in paper.output
    assert "byte-identical to the paper's published dataset" in paper.output
    other = CliRunner().invoke(app, ["data", "build", "--out", str(tmp_path / "s"), "--weather", "synthetic"])
    assert other.exit_code == 0, other.output
    assert "Open-Meteo" not in other.output and "byte-identical" not in other.output
    assert json.loads((tmp_path / "s" / MANIFEST_FILE).read_text())["weather_attribution"] is None
