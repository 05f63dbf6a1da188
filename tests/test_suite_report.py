"""Ranking and reporting suite roots (docs/suites.md#ranking-and-reporting-suite-runs): two held-out
months, 1 seed x 2 episodes. The board ranks by rliable's IQM as suite_stats computes it, never puts
a suite root beside a plain run or another split, and the report writes its tables and figures."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import read_csv_exact, sha256_file
from solarchain_eval.data.heldout import build_checked, heldout_dataset
from solarchain_eval.evaluation.suite_run import SUITE_METADATA_FILE, SUITE_SCORES_FILE
from solarchain_eval.evaluation.suite_stats import (
    aggregate_iqm,
    aggregate_optimality_gap,
    probability_of_improvement,
    stratified_bootstrap_interval,
)
from solarchain_eval.report import build_report
from solarchain_eval.report.leaderboard import make_leaderboards
from solarchain_eval.report.leaderboard.inputs import LeaderboardError
from solarchain_eval.report.options import LeaderboardOptions, ReportDataError
from solarchain_eval.tasks.suites import Suite, SuiteEntry, register_suite, unregister_suite
from submission_tarball import pack

runner = CliRunner()
SEEDS, EPISODES = (20260511,), 4
MONTHS = (1, 7)


@pytest.fixture(scope="module")
def months(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("months")
    return {f"m{m:02d}": build_checked(heldout_dataset("tmy-3sites", m), root / f"m{m:02d}") for m in MONTHS}


def _suite(name: str, split: str, months: dict[str, Path]) -> Suite:
    return Suite(
        name, f"two held-out months as {split}", tuple(SuiteEntry(n, "solar", split, d) for n, d in months.items())
    )


@pytest.fixture(scope="module")
def roots(months: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A suite root of static and myopic (test split), the same months as a train-split suite, and a plain run."""
    base = tmp_path_factory.mktemp("roots")
    suites = [_suite("two-months-rank", "test", months), _suite("two-months-tune", "train", months)]
    for suite in suites:
        register_suite(suite)
    try:
        common = {"seeds": SEEDS, "episodes": EPISODES}
        solarchain_eval.evaluate(["static", "myopic"], suite="two-months-rank", out=base / "heldout", **common)
        solarchain_eval.evaluate(["static"], suite="two-months-tune", out=base / "train", **common)
        solarchain_eval.evaluate(["static", "myopic"], data=months["m01"], out=base / "plain", **common)
    finally:
        for suite in suites:
            unregister_suite(suite.name)
    return {"heldout": base / "heldout", "train": base / "train", "plain": base / "plain"}


def _matrices(root: Path) -> dict[str, np.ndarray]:
    """Each policy's normalised score matrix, built here from suite_scores.csv (episodes x entries)."""
    scores = read_csv_exact(root / SUITE_SCORES_FILE)
    return {
        str(policy): group.pivot(index=["run_seed", "episode"], columns="entry", values="normalised")[
            [f"m{m:02d}" for m in MONTHS]
        ].to_numpy(float)
        for policy, group in scores.groupby("policy")
    }


def test_the_board_ranks_a_suite_root_by_its_iqm(roots, tmp_path):
    outcome = make_leaderboards([roots["heldout"]], tmp_path / "board")
    (board,) = outcome.boards
    assert board.suite is not None and board.suite.splits == ("test",) and outcome.notes == []
    ranked = board.sections[0].ranked
    matrices = _matrices(roots["heldout"])
    assert sorted(matrices) == ["myopic", "random", "static"]
    iqm = {p: aggregate_iqm(m) for p, m in matrices.items()}
    assert list(ranked["policy"]) == sorted(iqm, key=lambda p: -iqm[p])  # best IQM first
    assert list(ranked["rank"]) == [1, 2, 3]
    recorded = {r["policy"]: r for r in json.loads((roots["heldout"] / SUITE_METADATA_FILE).read_text())["aggregates"]}
    for row in ranked.to_dict("records"):
        matrix = matrices[row["policy"]]
        assert row["iqm"] == pytest.approx(iqm[row["policy"]], abs=1e-12)
        low, high = stratified_bootstrap_interval(matrix, aggregate_iqm, reps=2000, seed=0)
        assert (row["iqm_low"], row["iqm_high"]) == pytest.approx((low, high), abs=1e-12)
        assert row["optimality_gap"] == pytest.approx(aggregate_optimality_gap(matrix), abs=1e-12)
        assert row["mean"] == pytest.approx(matrix.mean(axis=0).mean(), abs=1e-12)
        assert row["p_improvement"] == pytest.approx(probability_of_improvement(matrix, matrices["myopic"]))
        # the board's default bootstrap is the suite's own: evaluate's recorded aggregates, to the bit
        assert row["iqm_low"] == recorded[row["policy"]]["iqm_low"] and row["iqm"] == recorded[row["policy"]]["iqm"]
        assert (row["entries"], row["episodes"], row["splits"]) == (2, EPISODES, "test")
    written = pd.read_csv(tmp_path / "board" / "leaderboard.csv")
    assert list(written["policy"]) == list(ranked["policy"]) and set(written["board_protocol_id"]) == {board.board_id}
    assert board.board_id == json.loads((roots["heldout"] / SUITE_METADATA_FILE).read_text())["protocol_id"]
    assert (tmp_path / "board" / "performance_profile.png").read_bytes()[:4] == b"\x89PNG"
    page = (tmp_path / "board" / "leaderboard.md").read_text()
    assert f"Suite protocol id: `{board.board_id}`" in page and "| 1 | Myopic |" in page


def test_a_suite_root_and_a_plain_run_are_never_on_one_board(roots, tmp_path):
    out = tmp_path / "mixed"
    with pytest.raises(LeaderboardError, match="is a suite root .* is not; a board never ranks suite results"):
        make_leaderboards([roots["heldout"], roots["plain"]], out)
    assert not out.exists()  # nothing half-written
    outcome = make_leaderboards([roots["plain"], roots["heldout"]], out, LeaderboardOptions(split=True))
    assert [b.sources for b in outcome.boards] == [[str(roots["plain"])], [str(roots["heldout"])]]
    assert [b.suite is not None for b in outcome.boards] == [False, True]
    (line,) = outcome.notes
    assert line.startswith("kept apart") and str(roots["plain"]) in line and str(roots["heldout"]) in line
    suite_board = outcome.boards[1]
    assert set(suite_board.frame()["source"]) == {str(roots["heldout"])}
    done = runner.invoke(
        app, ["leaderboard", str(roots["heldout"]), str(roots["plain"]), "--out", str(tmp_path / "cli")]
    )
    assert done.exit_code == 2 and "a board never ranks suite results beside single-task runs" in done.output
    assert "--split" in done.output and not (tmp_path / "cli").exists()


def test_suites_of_two_splits_are_kept_apart(roots, tmp_path):
    with pytest.raises(LeaderboardError, match="suites of different splits; a board never mixes splits"):
        make_leaderboards([roots["heldout"], roots["train"]], tmp_path / "mixed")
    outcome = make_leaderboards([roots["heldout"], roots["train"]], tmp_path / "split", LeaderboardOptions(split=True))
    assert [b.suite.splits for b in outcome.boards] == [("test",), ("train",)]
    assert len({b.board_id for b in outcome.boards}) == 2 and len(outcome.notes) == 1
    for board in outcome.boards:
        assert (tmp_path / "split" / board.board_id / "leaderboard.csv").is_file()
        assert set(board.frame()["splits"]) == {board.suite.splits[0]}
    # the same root twice: one board, each policy once, the repeat named
    (board,) = make_leaderboards([roots["heldout"], roots["heldout"]], tmp_path / "twice").boards
    assert len(board.sections[0].ranked) == 3 and any("repeats" in note for note in board.notes)


def test_the_report_of_a_suite_root_writes_its_tables_and_figures(roots, tmp_path):
    out = tmp_path / "report"
    outcome = build_report(roots["heldout"], out, formats=("md", "csv", "html"))
    names = {p.relative_to(out).as_posix() for p in outcome.files}
    for key in ("suite_entries", "suite_aggregates", "suite_improvement"):
        assert {f"tables/{key}.md", f"tables/{key}.csv"} <= names
    for key in ("suite_profile", "suite_heatmap"):
        assert (out / "figures" / f"{key}.png").read_bytes()[:4] == b"\x89PNG"
        assert (out / "figures" / f"{key}.svg").read_text().lstrip().startswith("<?xml")
    scores = read_csv_exact(roots["heldout"] / SUITE_SCORES_FILE)
    entries = pd.read_csv(out / "tables" / "suite_entries.csv").set_index("entry")
    for (entry, policy), value in scores.groupby(["entry", "policy"])["normalised"].mean().items():
        assert entries.loc[entry, policy] == pytest.approx(value, abs=1e-12)
    aggregates = pd.read_csv(out / "tables" / "suite_aggregates.csv")
    matrices = _matrices(roots["heldout"])
    assert list(aggregates["policy"]) == sorted(matrices, key=lambda p: -aggregate_iqm(matrices[p]))
    for row in aggregates.to_dict("records"):
        assert row["iqm"] == pytest.approx(aggregate_iqm(matrices[row["policy"]]), abs=1e-12)
    page = (out / "index.html").read_text()
    assert "suite_heatmap" in page and "data:image/png;base64," in page and 'id="suite_aggregates"' in page
    assert "suite protocol id" in (out / "report.md").read_text()
    done = runner.invoke(app, ["report", str(roots["heldout"]), "--out", str(tmp_path / "cli"), "--no-figures"])
    assert done.exit_code == 0, done.output
    assert "suite_aggregates" in done.output and (tmp_path / "cli" / "tables" / "suite_entries.md").is_file()


def test_an_edited_suite_root_is_refused(roots, tmp_path):
    edited = tmp_path / "edited"
    shutil.copytree(roots["heldout"], edited)
    scores_path = edited / SUITE_SCORES_FILE
    scores = read_csv_exact(scores_path)
    scores.loc[scores["policy"] == "static", "normalised"] += 0.5
    scores.to_csv(scores_path, index=False)
    with pytest.raises(ReportDataError, match="suite_scores.csv: its sha256 differs"):
        make_leaderboards([edited], tmp_path / "board")
    # vouched for again by hand: the scores no longer follow from the entries' runs
    meta_path = edited / SUITE_METADATA_FILE
    meta = json.loads(meta_path.read_text())
    meta["sha256"][SUITE_SCORES_FILE] = sha256_file(scores_path)
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ReportDataError, match="differ from those recomputed from the entries' runs"):
        build_report(edited, tmp_path / "report")
    assert not (tmp_path / "board").exists() and not (tmp_path / "report").exists()


def test_verify_checks_every_entry_and_the_suite_files(roots, tmp_path):
    done = runner.invoke(app, ["verify", str(roots["heldout"]), "--episodes", "1"])
    assert done.exit_code == 0, done.output
    assert [line for line in done.output.splitlines() if line.endswith(":")] == ["m01:", "m07:"]
    assert done.output.count("static: verified (1 episode)") == 2
    assert "suite files: checksums and scores match (suite two-months-rank" in done.output
    edited = tmp_path / "edited"
    shutil.copytree(roots["heldout"], edited)
    (edited / SUITE_SCORES_FILE).write_text((edited / SUITE_SCORES_FILE).read_text().replace("m07", "m7", 1))
    done = runner.invoke(app, ["verify", str(edited), "--episodes", "1"])
    assert done.exit_code == 1 and "suite files: FAIL" in done.output and "suite_scores.csv" in done.output
    assert done.output.count("static: verified (1 episode)") == 2  # the entries' runs are untouched


def test_a_packed_suite_root_is_ranked_as_the_folder_and_a_stray_file_refused(roots, tmp_path):
    folder = make_leaderboards([roots["heldout"]], tmp_path / "folder").boards[0]
    tarball = pack(tmp_path / "suite.tar.gz", roots["heldout"])
    done = runner.invoke(app, ["leaderboard", str(tarball), "--out", str(tmp_path / "packed")])
    assert done.exit_code == 0, done.output
    packed, unpacked = (pd.read_csv(tmp_path / name / "leaderboard.csv") for name in ("packed", "folder"))
    assert set(packed["source"]) == {str(tarball)}  # the board names what was submitted
    pd.testing.assert_frame_equal(packed.drop(columns="source"), unpacked.drop(columns="source"))
    assert folder.board_id in (tmp_path / "packed" / "leaderboard.md").read_text()
    # a file beside an entry's run files that its run_metadata.json does not record: refused, nothing written
    stray = pack(tmp_path / "stray.tar.gz", roots["heldout"], {"m01/notes.bin": b"\0" * 100})
    done = runner.invoke(app, ["leaderboard", str(stray), "--out", str(tmp_path / "never")])
    assert done.exit_code == 2 and "submission/m01/notes.bin is not vouched for" in done.output
    assert "pack only the suite root" in done.output and not (tmp_path / "never").exists()
