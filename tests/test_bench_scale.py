"""The scale benchmark's plumbing and the synthetic cities it builds on."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.data.cities import check_unique_prefixes, synthetic_cities
from solarchain_eval.perf.scale_bench import measure_scale, parse_scales


def test_synthetic_cities_are_stable_and_have_unique_prefixes():
    many = synthetic_cities(700)
    check_unique_prefixes(many)  # raises on a shared node-id prefix
    assert synthetic_cities(5) == many[:5]  # city i does not depend on the count
    assert all(22 <= c.latitude <= 40 and 100 <= c.longitude <= 122 for c in many)
    assert len({(c.latitude, c.longitude) for c in many}) == 700
    with pytest.raises(ValueError, match="1.."):
        synthetic_cities(0)


def test_parse_scales():
    assert parse_scales("5x10, 50X1") == ((5, 10), (50, 1))
    for bad in ("5x", "5*10", "0x3"):
        with pytest.raises(ValueError, match="scale"):
            parse_scales(bad)


def test_measure_scale_builds_loads_and_steps_a_small_dataset(tmp_path):
    result = measure_scale(2, 3, start="2026-06-01", end="2026-06-04", env_steps=500, num_envs=4, vector_calls=25,
                           repeats=1)  # fmt: skip
    assert (result.cities, result.nodes, result.hours) == (2, 6, 72)
    assert result.generation_rows == 6 * 72
    assert result.build_ms_per_node == pytest.approx(1000 * result.build_cpu_s / 6)
    assert result.build_cpu_s > 0 and result.load_cpu_s > 0
    assert result.env_steps_per_s > 0 and result.vector_env_steps_per_s > 0


def test_cli_writes_json_and_refuses_bad_scales(tmp_path):
    runner = CliRunner()
    out = tmp_path / "scale.json"
    args = ["bench-scale", "--end", "2026-04-03", "--env-steps", "1000", "--num-envs", "2", "--calls", "25"]
    result = runner.invoke(app, [*args, "--scales", "1x2", "--repeats", "1", "--json", str(out)])
    assert result.exit_code == 0, result.output
    rows = json.loads(out.read_text())
    assert rows[0]["nodes"] == 2 and rows[0]["generation_rows"] == 2 * 48
    result = runner.invoke(app, [*args, "--scales", "five"])
    assert result.exit_code == 2 and "--scales" in result.output
