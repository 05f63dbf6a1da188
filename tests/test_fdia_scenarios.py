"""Attack scenarios of ``data build``: rate, severity, uniform / clustered / stealthy patterns."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.data.build import DATASET_FILES, MANIFEST_FILE, build_dataset
from solarchain_eval.data.cities import City
from solarchain_eval.data.fdia import FdiaError, FdiaScenario, parse_severity
from solarchain_eval.data.published import PAPER_DATASET_SHA256
from solarchain_eval.data.synthetic import synthesize_weather
from solarchain_eval.data.table import load_table

CITIES = (City("Wuhan", 30.5928, 114.3055), City("Xian", 34.3416, 108.9398), City("Kunming", 25.0389, 102.7183))
START, END, NODES = "2026-06-01", "2026-06-08", 5  # 3 cities x 5 nodes x 168 hours = 2,520 records


@pytest.fixture(scope="module")
def weather():
    return synthesize_weather(CITIES, START, END, 3, "Asia/Shanghai")


def _build(weather, out, scenario=None):
    build_dataset(
        weather,
        out,
        cities=CITIES,
        seed=3,
        start=START,
        end=END,
        nodes_per_city=NODES,
        timezone="Asia/Shanghai",
        weather_source="synthetic",
        fdia=scenario,
    )
    generation = pd.read_csv(out / "spatiotemporal_generation.csv")
    return generation, json.loads((out / MANIFEST_FILE).read_text())


def test_default_scenario_reproduces_the_published_files_and_is_recorded(tmp_path, paper_weather):
    out = tmp_path / "paper"
    result = CliRunner().invoke(
        app, ["data", "build", "--out", str(out), "--weather-cache", str(paper_weather), "--fdia-rate", "0.05"]
    )
    assert result.exit_code == 0, result.output
    for name in DATASET_FILES:
        assert sha256_file(out / name) == PAPER_DATASET_SHA256[name], name
    fdia = json.loads((out / MANIFEST_FILE).read_text())["fdia"]
    assert fdia["injected_records"] == 1_800 and fdia["pattern"] == "uniform" and fdia["rate"] == 0.05
    assert fdia["severity"] == "paper multipliers"


@pytest.mark.parametrize("pattern", ["uniform", "clustered", "stealthy"])
@pytest.mark.parametrize("rate", [0.0, 0.013, 0.2])
def test_rate_sets_the_number_of_injected_records(tmp_path, weather, pattern, rate):
    generation, manifest = _build(weather, tmp_path, FdiaScenario(rate=rate, pattern=pattern))
    expected = int(np.round(rate * len(generation)))
    assert int(generation["fdia_detected"].sum()) == expected == manifest["fdia"]["injected_records"]
    assert ((generation["verification_status"] == "rejected") == generation["fdia_detected"]).all()


def test_uniform_severity_range_bounds_the_daylight_multipliers(tmp_path, weather):
    generation, manifest = _build(weather, tmp_path, FdiaScenario(rate=0.1, severity=(2.0, 2.5)))
    hit = generation[generation["fdia_detected"] & (generation["P_max_W"] > 1)]
    ratio = hit["P_reported_W"] / hit["P_max_W"]
    assert len(hit) > 50
    assert ratio.min() >= 2.0 - 1e-3 and ratio.max() <= 2.5 + 1e-3
    assert ratio.max() - ratio.min() > 0.3  # a range, not one value
    assert manifest["fdia"]["severity"] == [2.0, 2.5]


def test_stealthy_readings_stay_under_p_max_and_only_the_flag_sees_them(tmp_path, weather):
    generation, manifest = _build(weather, tmp_path, FdiaScenario(rate=0.1, pattern="stealthy", severity=(0.9, 1.6)))
    hit = generation[generation["fdia_detected"]]
    assert len(hit) == round(0.1 * len(generation))
    assert (hit["P_max_W"] > 1).all()  # daylight only
    assert (hit["P_reported_W"] <= hit["P_max_W"]).all()
    assert (hit["P_reported_W"] == hit["P_max_W"]).mean() > 0.5  # m >= 1 is capped at P_max
    assert (hit["verification_status"] == "rejected").all()
    # The physics check (excess over P_max) sees none of them: the table's excess energy is
    # exactly that of the honest records (measurement noise); the benchmark still counts them
    # as violations, through the flag.
    table = load_table(tmp_path)
    excess = np.maximum(generation["P_reported_W"] - generation["P_max_W"], 0.0)
    assert excess[generation["fdia_detected"]].sum() == 0.0
    assert table.excess_mwh.sum() == pytest.approx(excess[~generation["fdia_detected"]].sum() / 1e6, rel=1e-9)
    violating = generation["fdia_detected"] | (excess > 1e-6)
    assert table.rejected_mwh.sum() == pytest.approx(generation["P_reported_W"][violating].sum() / 1e6, rel=1e-9)
    assert table.rejected_mwh.sum() > 1.2 * generation["P_reported_W"][excess > 1e-6].sum() / 1e6


def test_a_non_stealthy_attack_exceeds_p_max(tmp_path, weather):
    generation, _ = _build(weather, tmp_path, FdiaScenario(rate=0.1, pattern="uniform"))
    hit = generation[generation["fdia_detected"]]
    assert (hit["P_reported_W"] > hit["P_max_W"] + 1e-6).mean() > 0.5


def test_clustered_bursts_are_contiguous_in_one_city(tmp_path, weather):
    generation, manifest = _build(weather, tmp_path, FdiaScenario(rate=0.1, pattern="clustered", burst_hours=4))
    fdia = manifest["fdia"]
    assert sum(b["records"] for b in fdia["bursts"]) == fdia["injected_records"] == generation["fdia_detected"].sum()
    times = sorted(generation["timestamp"].unique())
    index = {t: i for i, t in enumerate(times)}
    hit = generation[generation["fdia_detected"]]
    covered = set()
    for burst in fdia["bursts"]:
        assert burst["hours"] <= 4
        first = index[burst["first_timestamp"]]
        window = set(times[first : first + burst["hours"]])
        rows = hit[(hit["city"] == burst["city"]) & hit["timestamp"].isin(window)]
        covered |= set(rows.index)
    assert covered == set(hit.index)  # every injected record lies in a burst's city-time window
    # Full bursts cover every node of their city in each of their hours.
    full = [b for b in fdia["bursts"] if b["records"] == 4 * NODES]
    assert len(full) >= len(fdia["bursts"]) - 2
    # Far fewer (city, hour) cells than a uniform attack of the same size touches.
    cells = hit.groupby(["city", "timestamp"]).ngroups
    uniform, _ = _build(weather, tmp_path / "u", FdiaScenario(rate=0.1))
    assert cells * 2 < uniform[uniform["fdia_detected"]].groupby(["city", "timestamp"]).ngroups


def test_scenarios_are_deterministic(tmp_path, weather):
    scenario = FdiaScenario(rate=0.07, pattern="clustered", severity=(1.1, 1.3))
    a, _ = _build(weather, tmp_path / "a", scenario)
    b, _ = _build(weather, tmp_path / "b", scenario)
    pd.testing.assert_frame_equal(a, b)


def test_bad_scenarios_are_one_line_errors(tmp_path):
    with pytest.raises(FdiaError, match="LO:HI"):
        parse_severity("1.5")
    with pytest.raises(FdiaError, match="0 <= LO <= HI"):
        parse_severity("2:1")
    with pytest.raises(FdiaError, match="pattern 'burst'"):
        FdiaScenario(pattern="burst")
    out = tmp_path / "x"
    result = CliRunner().invoke(
        app, ["data", "build", "--out", str(out), "--nodes-per-city", "1", "--fdia-severity", "a:b"]
    )
    assert result.exit_code == 2 and "fdia severity 'a:b'" in result.output
    assert not out.exists() or not any(out.iterdir())
