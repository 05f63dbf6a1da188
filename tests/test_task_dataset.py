"""A task's dataset builder (tasks/dataset.py): the optional capability and the solar market's one.

The solar builder wraps data/'s functions; these tests check that it builds the same bytes as
calling them directly, and that a task without a builder is a one-line error.
"""

from __future__ import annotations

import types
from pathlib import Path

import pytest
from typer.testing import CliRunner

from solarchain_eval.common.errors import OptionsError
from solarchain_eval.data.build import DATASET_FILES, MANIFEST_FILE, build_dataset
from solarchain_eval.data.cities import PAPER_CITIES, City, synthetic_cities
from solarchain_eval.data.fdia import FdiaScenario, fdia_pattern_help
from solarchain_eval.data.splits import SPLIT_RULE, SPLITS
from solarchain_eval.data.synthetic import SYNTHETIC_SOURCE, synthesize_weather
from solarchain_eval.tasks import DatasetBuilder, NoDatasetBuilderError, dataset_of, get_task, has_dataset_builder


def _files(folder: Path) -> dict[str, bytes]:
    return {name: (folder / name).read_bytes() for name in (*DATASET_FILES, MANIFEST_FILE)}


def test_a_task_without_a_builder_is_a_one_line_error():
    bare = types.SimpleNamespace(name="bare-market")
    assert not has_dataset_builder(bare)
    with pytest.raises(NoDatasetBuilderError, match=r"^task 'bare-market' has no dataset builder$") as caught:
        dataset_of(bare)
    assert isinstance(caught.value, OptionsError)  # the command line reports it in one line, exit 2


def test_the_solar_task_supplies_its_builder():
    solar = get_task("solar")
    builder = dataset_of(solar)
    assert has_dataset_builder(solar) and isinstance(builder, DatasetBuilder)
    assert builder.files == DATASET_FILES and builder.manifest == MANIFEST_FILE == solar.dataset_manifest
    assert builder.false_data.patterns == ("uniform", "clustered", "stealthy")
    assert builder.false_data.pattern_help("--x") == fdia_pattern_help("--x")
    assert builder.weather_sources == ("paper", "synthetic", "open-meteo")
    assert builder.split_rule == SPLIT_RULE
    assert [s.name for s in builder.splits()] == list(SPLITS)
    assert {s.name: s.datasets for s in builder.splits()} == {s.name: s.datasets for s in SPLITS.values()}


def test_the_builders_cities():
    builder = dataset_of(get_task("solar"))
    assert builder.cities(None) == PAPER_CITIES
    assert builder.cities(3) == synthetic_cities(3)
    assert builder.cities(["Wuhan:30.5:114.3"]) == (City("Wuhan", 30.5, 114.3),)
    with pytest.raises(ValueError, match="share the node-id prefix 'WUH'"):
        builder.cities(["Wuhan:30.5:114.3", "Wuhai:39.6:106.8"])


def test_the_solar_builder_builds_the_bytes_of_a_direct_build(tmp_path):
    """Differential: the builder's weather and build against data/'s functions called directly."""
    builder = dataset_of(get_task("solar"))
    cities = synthetic_cities(2)
    args = dict(seed=7, start="2026-06-01", end="2026-06-03", nodes_per_city=2, timezone="Asia/Shanghai")
    scenario = builder.scenario(0.2, "1.2:1.6", "clustered", 3)
    assert scenario == FdiaScenario(0.2, (1.2, 1.6), "clustered", 3)

    weather = builder.choose_weather(cities, "2026-06-01", "2026-06-03", seed=7, timezone="Asia/Shanghai",
                                     source="synthetic")  # fmt: skip
    manifest = builder.build(weather, tmp_path / "via", cities=cities, scenario=scenario, **args)
    direct = build_dataset(
        synthesize_weather(cities, "2026-06-01", "2026-06-03", 7, "Asia/Shanghai"),
        tmp_path / "direct",
        cities=cities,
        weather_source=SYNTHETIC_SOURCE,
        fdia=FdiaScenario(0.2, (1.2, 1.6), "clustered", 3),
        **args,
    )
    assert manifest == direct.manifest
    assert _files(tmp_path / "via") == _files(tmp_path / "direct")
    assert manifest["fdia"]["pattern"] == "clustered" and manifest["fdia"]["injected_records"] > 0
    assert manifest["files"][builder.node_records_file]["rows"] == 2 * 2 * 48


def test_the_builders_check_summarises_a_valid_dataset(tiny_dataset):
    from solarchain_eval.data.load import load_raw_dataset

    raw = load_raw_dataset(tiny_dataset)
    rows = dict(dataset_of(get_task("solar")).check(tiny_dataset))
    assert list(rows)[:3] == ["hours", "cities", "nodes"]
    assert rows["hours"] == f"{raw.hours:,} from {raw.first_timestamp.isoformat()}"
    assert rows["nodes"] == f"{raw.generation['node_id'].nunique():,}"
    assert rows["FDIA-labelled records"] == f"{int(raw.generation['fdia_detected'].sum()):,}"
    assert rows["trades"] == f"{len(raw.trades):,}"


def test_data_check_prints_the_builders_rows(tiny_dataset):
    from solarchain_eval.cli import app

    result = CliRunner().invoke(app, ["data", "check", str(tiny_dataset)])
    assert result.exit_code == 0, result.output
    for what, value in dataset_of(get_task("solar")).check(tiny_dataset):
        assert what in result.output and value in result.output
