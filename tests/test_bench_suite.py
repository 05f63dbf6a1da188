"""``bench-suite``: its counts are what it did, and the datasets it builds are ``data build-family``'s."""

from __future__ import annotations

import json
import os

import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app

runner = CliRunner()


@pytest.mark.slow
def test_bench_suite_counts_what_it_built_and_ran_and_builds_the_family_bytes(tmp_path):
    cache, out, figures, family = tmp_path / "cache", tmp_path / "suite", tmp_path / "bench.json", tmp_path / "family"
    cache_before = os.environ.get("SOLARCHAIN_CACHE_DIR")
    args = ["bench-suite", "--build", "heldout", "--entries", "1", "--seeds", "1", "--episodes", "1"]
    result = runner.invoke(app, [*args, "--cache", str(cache), "--out", str(out), "--json", str(figures)])
    assert result.exit_code == 0, result.output
    assert os.environ.get("SOLARCHAIN_CACHE_DIR") == cache_before  # the bench's cache was put back
    bench = json.loads(figures.read_text())

    # datasets: the one entry asked for, each built into the (kept) cache and nothing else
    built = sorted(p.name for p in (cache / "datasets").iterdir() if (p / "manifest.json").is_file())
    assert built == ["tmy-3sites-01"]
    assert bench["datasets_built"] == len(built) == len(bench["datasets"])
    assert [d["name"] for d in bench["datasets"]] == built
    # episodes: 1 entry x 3 policies x 1 seed x 1 episode, as written in the suite root
    scores = pd.read_csv(out / "suite_scores.csv")
    metrics = pd.read_csv(out / "tmy-3sites-01" / "metrics.csv")
    assert bench["episodes"] == len(scores) == len(metrics) == 3
    assert sorted(scores["policy"]) == ["myopic", "random", "static"]
    assert bench["reference_episodes"] == 3
    assert (bench["entries"], bench["run_seeds"], bench["episodes_per_seed"]) == (1, 1, 1)
    assert bench["complete"] is False and "n/a (partial run)" in result.output
    assert bench["build_ratio"] == pytest.approx(bench["build_s"] / bench["reference_build_s"])
    assert json.loads((out / "suite_metadata.json").read_text())["protocol_id"] == bench["suite_protocol_id"]

    # the bench's dataset is byte for byte the one `data build-family` writes
    made = runner.invoke(app, ["data", "build-family", "tmy-3sites", "--month", "1", "--out", str(family)])
    assert made.exit_code == 0, made.output
    ours, theirs = cache / "datasets" / "tmy-3sites-01", family / "tmy-3sites-01"
    names = sorted(p.name for p in theirs.iterdir())
    assert sorted(p.name for p in ours.iterdir()) == names and len(names) == 5
    for name in names:
        assert (ours / name).read_bytes() == (theirs / name).read_bytes(), name


def test_bench_suite_refuses_a_cache_that_is_not_empty_before_any_work(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / "old").write_text("x")
    figures = tmp_path / "bench.json"
    result = runner.invoke(app, ["bench-suite", "--cache", str(cache), "--json", str(figures)])
    assert result.exit_code == 2
    assert "--cache" in result.output and str(cache) in result.output
    assert not figures.exists() and sorted(p.name for p in cache.iterdir()) == ["old"]


def test_bench_suite_refuses_an_unknown_suite(tmp_path):
    result = runner.invoke(app, ["bench-suite", "--build", "heldout,nope", "--json", str(tmp_path / "b.json")])
    assert result.exit_code == 2 and "nope" in result.output
    assert not (tmp_path / "b.json").exists()
