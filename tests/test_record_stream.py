"""Records streamed to disk as episodes finish: the same bytes as the all-at-once writer, flat
memory, Parquet step tables that every reader takes, and runs too large for the disk refused."""

from __future__ import annotations

import json
import shutil
import tracemalloc
from collections import namedtuple
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import read_csv_exact
from solarchain_eval.data.table import load_table
from solarchain_eval.evaluation import record_stream
from solarchain_eval.evaluation.record_stream import RecordStream, estimate_bytes
from solarchain_eval.evaluation.records import (
    ACTIONS_FILE,
    ACTIONS_PARQUET,
    CITY_HOUR_FILE,
    CITY_HOUR_PARQUET,
    METADATA_FILE,
    write_records,
)
from solarchain_eval.evaluation.rundir import verify_run_dir
from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation
from solarchain_eval.governance import AgenticOptions
from solarchain_eval.governance.wrapper import EXTRA_METRICS_KEY
from solarchain_eval.report.loading import load_report_data


def _spec(data: Path, *, episodes: int = 3, agentic: AgenticOptions | None = None, policies=None) -> EvaluationSpec:
    return EvaluationSpec(
        policies=policies or ["static", "random", "myopic"],
        run_seeds=(0, 7),
        episodes=episodes,
        data_dir=data,
        agentic=agentic,
    )


def _record_files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.name != METADATA_FILE}


@pytest.mark.parametrize("flush_steps", [30, 10**9], ids=["many-chunks", "one-chunk"])
@pytest.mark.parametrize("governed", [False, True], ids=["plain", "planner-auditor"])
def test_streamed_files_are_byte_identical_to_the_all_at_once_writer(
    tiny_dataset, tmp_path, monkeypatch, flush_steps, governed
):
    monkeypatch.setattr(record_stream, "FLUSH_STEPS", flush_steps)
    spec = _spec(tiny_dataset, agentic=AgenticOptions() if governed else None)
    outcome = run_evaluation(spec, tmp_path / "run")
    streamed = _record_files(tmp_path / "run")
    # the writer of every earlier version, fed the same episodes
    write_records(tmp_path / "whole", outcome.results, load_table(tiny_dataset).cities)
    whole = _record_files(tmp_path / "whole")
    expected = {"metrics.csv", ACTIONS_FILE, CITY_HOUR_FILE, "summary.json"}
    if governed:
        expected |= {"agentic_logs.jsonl", "governance_diagnostics.csv"}
    assert set(streamed) == set(whole) == expected
    for name in whole:
        assert streamed[name] == whole[name], name
    metadata = json.loads((tmp_path / "run" / METADATA_FILE).read_text())
    assert metadata["rows"] == {"metrics": 18, "actions": sum(r.n_steps for r in outcome.results)}
    assert verify_run_dir(tmp_path / "run") == []


def test_metrics_columns_that_appear_in_later_chunks_are_written_as_all_at_once(tiny_dataset, tmp_path, monkeypatch):
    """Extra metrics columns only some episodes have (an int one, a text one) across chunks."""
    monkeypatch.setattr(record_stream, "FLUSH_STEPS", 40)
    results = run_evaluation(_spec(tiny_dataset), tmp_path / "run").results
    for index, result in enumerate(results):
        if index >= 7:
            result.extras[EXTRA_METRICS_KEY] = {"late_count": index, **({"note": "odd"} if index % 2 else {})}
    cities = load_table(tiny_dataset).cities
    with RecordStream(tmp_path / "streamed", cities) as stream:
        for result in results:
            stream.add(result)
        stream.finish()
    write_records(tmp_path / "whole", results, cities)
    assert _record_files(tmp_path / "streamed") == _record_files(tmp_path / "whole")
    assert "late_count" in (tmp_path / "whole" / "metrics.csv").read_text().splitlines()[0]


def test_without_kept_results_the_files_and_summary_are_the_same(tiny_dataset, tmp_path):
    kept = run_evaluation(_spec(tiny_dataset), tmp_path / "kept")
    dropped = run_evaluation(_spec(tiny_dataset), tmp_path / "dropped", keep_results=False)
    assert dropped.results == [] and dropped.episodes == kept.episodes == 18
    assert dropped.summary == kept.summary == json.loads((tmp_path / "kept" / "summary.json").read_text())
    assert _record_files(tmp_path / "kept") == _record_files(tmp_path / "dropped")


def test_memory_stays_flat_in_the_number_of_episodes(tiny_dataset, tmp_path, monkeypatch):
    """The peak of Python allocations for 10x the episodes stays within a small margin (every
    episode kept until the end grew it about tenfold)."""
    monkeypatch.setattr(record_stream, "FLUSH_STEPS", 24 * 20)
    peaks = {}
    for episodes in (20, 200):
        spec = EvaluationSpec(policies=["static"], run_seeds=(0,), episodes=episodes, data_dir=tiny_dataset)
        tracemalloc.start()
        try:
            run_evaluation(spec, tmp_path / str(episodes), keep_results=False)
            peaks[episodes] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert peaks[200] < 1.3 * peaks[20], peaks


def test_parquet_step_tables_hold_the_csv_values_and_every_reader_takes_them(tiny_dataset, tmp_path, monkeypatch):
    monkeypatch.setattr(record_stream, "FLUSH_STEPS", 30)  # several row groups
    csv_run, parquet_run = tmp_path / "csv", tmp_path / "parquet"
    run_evaluation(_spec(tiny_dataset), csv_run, keep_results=False)
    run_evaluation(_spec(tiny_dataset), parquet_run, keep_results=False, step_format="parquet")
    names = {p.name for p in parquet_run.iterdir()}
    assert {ACTIONS_PARQUET, CITY_HOUR_PARQUET} <= names and not {ACTIONS_FILE, CITY_HOUR_FILE} & names
    assert (parquet_run / "metrics.csv").read_bytes() == (csv_run / "metrics.csv").read_bytes()
    for csv_name, parquet_name in ((ACTIONS_FILE, ACTIONS_PARQUET), (CITY_HOUR_FILE, CITY_HOUR_PARQUET)):
        pd.testing.assert_frame_equal(pd.read_parquet(parquet_run / parquet_name), read_csv_exact(csv_run / csv_name))
    metadata = json.loads((parquet_run / METADATA_FILE).read_text())
    assert {ACTIONS_PARQUET, CITY_HOUR_PARQUET} <= set(metadata["files"])
    assert verify_run_dir(parquet_run) == []  # checksums cover the Parquet files
    from_csv, from_parquet = load_report_data(csv_run), load_report_data(parquet_run)
    pd.testing.assert_frame_equal(from_parquet.actions, from_csv.actions, check_exact=False, rtol=1e-15)
    pd.testing.assert_frame_equal(from_parquet.city_hour, from_csv.city_hour, check_exact=False, rtol=1e-15)
    assert from_parquet.sources[ACTIONS_FILE] == [parquet_run / ACTIONS_PARQUET]
    # a changed Parquet file is caught like a changed CSV
    (parquet_run / ACTIONS_PARQUET).write_bytes((parquet_run / ACTIONS_PARQUET).read_bytes() + b"\0")
    assert any(ACTIONS_PARQUET in problem for problem in verify_run_dir(parquet_run))


@pytest.mark.parametrize("step_format", ["csv", "parquet"])
def test_the_disk_estimate_covers_the_files_without_doubling_them(tiny_dataset, tmp_path, step_format):
    spec = _spec(tiny_dataset, episodes=30)
    run_evaluation(spec, tmp_path / "run", keep_results=False, step_format=step_format)
    written = sum(p.stat().st_size for p in (tmp_path / "run").iterdir())
    table = load_table(tiny_dataset)
    estimate = estimate_bytes(180, spec.config.episode_steps, len(table.cities), step_format)
    assert written <= estimate <= 2 * written, (written, estimate)


def _evaluate(data: Path, out: Path, *extra: str):
    args = ["evaluate", "--data", str(data), "--policies", "static", "--seeds", "0", "--out", str(out), *extra]
    return CliRunner().invoke(app, args)


def test_a_run_too_large_for_the_disk_is_refused_before_any_work(tiny_dataset, tmp_path):
    out = tmp_path / "runs" / "huge"
    result = _evaluate(tiny_dataset, out, "--episodes", "1000000000")
    assert result.exit_code == 2, result.output
    line = result.output.strip().splitlines()[-1]
    assert line.startswith("error: --out ") and "1,000,000,000 episodes of 24 steps would write about" in line, line
    assert " TB of records" in line and " free;" in line, line
    assert not out.exists() and not (tmp_path / "runs").exists()  # nothing written, not even the parent


def test_the_free_space_decides(tiny_dataset, tmp_path, monkeypatch):
    usage = namedtuple("usage", "total used free")
    estimate = estimate_bytes(2, 24, 3, "csv") + record_stream.DISK_MARGIN_BYTES
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10 * estimate, 0, estimate - 1))
    assert _evaluate(tiny_dataset, tmp_path / "a", "--episodes", "2").exit_code == 2
    assert not (tmp_path / "a").exists()
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10 * estimate, 0, estimate))
    result = _evaluate(tiny_dataset, tmp_path / "b", "--episodes", "2")
    assert result.exit_code == 0, result.output


def test_progress_lines_with_an_eta_on_a_non_terminal(tiny_dataset, tmp_path, monkeypatch):
    from solarchain_eval.cli import progress

    monkeypatch.setattr(progress, "PLAIN_EVERY_S", 0.0)
    result = _evaluate(tiny_dataset, tmp_path / "run", "--episodes", "4")
    assert result.exit_code == 0, result.output
    lines = [line for line in result.output.splitlines() if line.startswith("evaluating: ")]
    assert len(lines) == 4, result.output
    assert lines[0].startswith("evaluating: 1/4 episodes (25.0%), ") and " ETA " in lines[0]
    assert lines[-1].startswith("evaluating: 4/4 episodes (100.0%), ") and lines[-1].endswith("ETA 0:00")


def test_plain_progress_lines_come_at_most_every_interval():
    import io

    from rich.console import Console

    from solarchain_eval.cli.progress import count_progress

    now = [100.0]
    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    with count_progress("evaluating", 90_000, console=console, every_s=10.0, clock=lambda: now[0]) as advance:
        for _ in range(3):  # 3 episodes in 6 s: no line yet
            now[0] += 2.0
            advance(1)
        now[0] += 4.0  # 10 s after the start: 5,000 more episodes
        advance(5_000)
        now[0] += 1.0
        advance(1)
    assert out.getvalue().splitlines() == ["evaluating: 5,003/90,000 episodes (5.6%), 500.3 episodes/s, ETA 2:50"]
