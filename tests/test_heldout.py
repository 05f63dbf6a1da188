"""The held-out family tmy-3sites: shipped weather, byte-reproducible months, design checks, CLI."""

from __future__ import annotations

import hashlib
import json
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.data import heldout
from solarchain_eval.data.cities import DEFAULT_SEED
from solarchain_eval.data.errors import DatasetError
from solarchain_eval.data.files import DATASET_FILES, GENERATION_FILE, MANIFEST_FILE
from solarchain_eval.data.heldout import (
    TMY_FAMILY,
    build_checked,
    build_heldout,
    family_datasets,
    heldout_dataset,
    pinned_sha256,
)
from solarchain_eval.data.weather import WeatherError

ROOT = Path(__file__).resolve().parents[1]
#: April of tmy-3sites, pinned here as well as in the package's SHA256SUMS.
APRIL_SHA256 = {
    "urban_energy_nodes.csv": "86ad94eb1d7da192ce72f1081b1bf7aa6f81b13cf8bd524ac8e9b076452f7b38",
    "spatiotemporal_generation.csv": "3071dd829a96fadd93077c01bf4fa5a7b881ac356a91f8963fa4e39066ed491c",
    "market_liquidity.csv": "5a937297e7870eab355552b0dc0221dd62bbc58f16b9033b011c92f72d9759f8",
    "p2p_trades.csv": "519963d1220c5c10b43abe955a483814a23c9a4656bb46985b604606cd7103e7",
}


def test_the_shipped_weather_is_pvlibs_files_byte_for_byte():
    pvlib = pytest.importorskip("pvlib")
    for city, name in heldout.TMY_SITES:
        digest = hashlib.sha256((Path(pvlib.__file__).parent / "data" / name).read_bytes()).hexdigest()
        assert heldout._SUMS[name] == digest, city
    read = dict(heldout.read_tmy_files())
    assert [(c, read[c].path.name, read[c].format) for c, _ in heldout.TMY_SITES] == [
        ("Greensboro", "723170TYA.CSV", "tmy3"),
        ("Sand Point", "703165TY.csv", "tmy3"),
        ("Miami", "12839.tm2", "tmy2"),
    ]


def test_a_damaged_payload_is_refused(monkeypatch):
    from solarchain_eval.data.published import PackagedWeatherError

    monkeypatch.setattr(heldout, "_SUMS", dict(heldout._SUMS, **{"703165TY.csv": "f" * 64}))
    heldout.read_tmy_files.cache_clear()
    try:
        with pytest.raises(PackagedWeatherError, match=r"703165TY.csv.xz is damaged: sha256 f0333a68.*not ffff"):
            heldout.read_tmy_files()
    finally:
        heldout.read_tmy_files.cache_clear()


def test_the_payload_is_package_data():
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    package = ROOT / "src" / "solarchain_eval"
    shipped = {p for pattern in patterns["solarchain_eval"] for p in package.glob(pattern)}
    wanted = {package / "data" / "tmy" / f"{name}.xz" for _, name in heldout.TMY_SITES}
    assert wanted | {package / "data" / "tmy" / "SHA256SUMS"} <= shipped


def test_the_family_is_twelve_months_of_2027():
    months = family_datasets(TMY_FAMILY)
    assert [d.name for d in months] == [f"tmy-3sites-{m:02d}" for m in range(1, 13)]
    assert (months[0].start, months[0].end, months[11].start, months[11].end) == (
        "2027-01-01",
        "2027-02-01",
        "2027-12-01",
        "2028-01-01",
    )
    assert [d.seed for d in months] == [DEFAULT_SEED + m for m in range(1, 13)]
    assert {(d.timezone, d.nodes_per_city) for d in months} == {("Etc/GMT+9", 10)}
    assert all(len(pinned_sha256(d.name)) == 4 for d in months)
    with pytest.raises(WeatherError, match="month must be 1..12"):
        heldout_dataset(TMY_FAMILY, 13)


@pytest.fixture(scope="module")
def april(tmp_path_factory):
    return build_heldout(heldout_dataset(TMY_FAMILY, 4), tmp_path_factory.mktemp("april"))


def test_a_month_is_byte_reproducible_and_pinned(april, tmp_path):
    again = build_heldout(heldout_dataset(TMY_FAMILY, 4), tmp_path / "again")
    first = {name: sha256_file(april.out_dir / name) for name in DATASET_FILES}
    assert first == {name: sha256_file(again.out_dir / name) for name in DATASET_FILES}
    assert first == APRIL_SHA256 == pinned_sha256("tmy-3sites-04")


def test_the_manifest_records_source_sites_and_licence(april):
    manifest = json.loads((april.out_dir / MANIFEST_FILE).read_text())
    assert (manifest["start"], manifest["end"], manifest["timezone"]) == ("2027-04-01", "2027-05-01", "Etc/GMT+9")
    assert manifest["seed"] == DEFAULT_SEED + 4 and manifest["hours"] == 720 and manifest["family"] == TMY_FAMILY
    assert [c["name"] for c in manifest["cities"]] == ["Greensboro", "Sand Point", "Miami"]
    assert [(e["file"], e["format"], e["site"]["utc_offset_h"]) for e in manifest["weather_files"]] == [
        ("723170TYA.CSV", "tmy3", -5.0),
        ("703165TY.csv", "tmy3", -9.0),
        ("12839.tm2", "tmy2", -5),
    ]
    assert [e["sha256"] for e in manifest["weather_files"]] == [heldout._SUMS[n] for _, n in heldout.TMY_SITES]
    assert manifest["weather_attribution"]["source_url"] == "https://nsrdb.nrel.gov/"
    assert manifest["fdia"]["rate"] == 0.05 and manifest["fdia"]["severity"] == "paper multipliers"


def test_every_city_has_its_daylight_inside_one_market_day(tmp_path):
    """UTC-9 puts each city's daylight inside one day of the market clock (June: Sand Point's longest days)."""
    june = build_heldout(heldout_dataset(TMY_FAMILY, 6), tmp_path / "june")
    generation = pd.read_csv(june.out_dir / GENERATION_FILE, usecols=["hour", "city", "irradiance_Wm2"])
    lit = generation[generation["irradiance_Wm2"] > 0].groupby("city")["hour"].agg(["min", "max"])
    assert lit.to_dict("index") == {
        "Greensboro": {"min": 2, "max": 15},
        "Miami": {"min": 2, "max": 15},
        "Sand Point": {"min": 6, "max": 22},
    }


def test_a_rebuild_that_differs_writes_nothing(tmp_path, monkeypatch):
    wrong = dict(heldout._SUMS, **{"tmy-3sites-04/market_liquidity.csv": "0" * 64})
    monkeypatch.setattr(heldout, "_SUMS", wrong)
    target = tmp_path / "tmy-3sites-04"
    with pytest.raises(DatasetError, match="market_liquidity.csv has sha256 5a937297.*the shipped one 0000"):
        build_checked(heldout_dataset(TMY_FAMILY, 4), target)
    assert list(tmp_path.iterdir()) == []


def test_cached_months_and_the_cli(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from solarchain_eval.cli import app

    monkeypatch.setenv("SOLARCHAIN_CACHE_DIR", str(tmp_path / "cache"))
    cached = heldout.heldout_dataset_dir(TMY_FAMILY, 2)
    assert cached == tmp_path / "cache" / "datasets" / "tmy-3sites-02"
    assert {n: sha256_file(cached / n) for n in DATASET_FILES} == pinned_sha256("tmy-3sites-02")
    result = CliRunner().invoke(app, ["data", "build-family", TMY_FAMILY, "--out", str(tmp_path / "f"), "--month", "2"])
    assert result.exit_code == 0, result.output
    assert "match the shipped ones" in result.output
    assert {n: sha256_file(tmp_path / "f" / "tmy-3sites-02" / n) for n in DATASET_FILES} == pinned_sha256(
        "tmy-3sites-02"
    )
    again = CliRunner().invoke(app, ["data", "build-family", TMY_FAMILY, "--out", str(tmp_path / "f"), "--month", "2"])
    assert again.exit_code == 2 and "already holds a dataset" in again.output
    unknown = CliRunner().invoke(app, ["data", "build-family", "nope", "--out", str(tmp_path / "g")])
    assert unknown.exit_code == 2 and "unknown held-out family 'nope'" in unknown.output
    assert not (tmp_path / "g").exists()
