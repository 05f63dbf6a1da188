"""Suite evaluation: two held-out months, 1 seed x 2 episodes; the suite root, its scores, the
differential against per-entry evaluations, the command line, and refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import read_csv_exact, sha256_file
from solarchain_eval.data.heldout import build_checked, heldout_dataset
from solarchain_eval.evaluation.fingerprint import canonical_json, sha256_text
from solarchain_eval.evaluation.suite_run import (
    PROFILE_FILE,
    SUITE_METADATA_FILE,
    SUITE_SCORES_FILE,
    SuiteScoreError,
    entry_scores,
    matrices,
)
from solarchain_eval.evaluation.suite_stats import aggregate_iqm
from solarchain_eval.tasks.suites import (
    Suite,
    SuiteEntry,
    SuiteError,
    UnknownSuiteError,
    get_suite,
    register_suite,
    unregister_suite,
)

runner = CliRunner()
SEEDS, EPISODES = (20260511,), 2
MONTHS = (1, 7)


@pytest.fixture(scope="module")
def months(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("months")
    return {f"m{m:02d}": build_checked(heldout_dataset("tmy-3sites", m), root / f"m{m:02d}") for m in MONTHS}


@pytest.fixture(scope="module")
def two_months(months: dict[str, Path]):
    suite = Suite(
        "two-months", "two held-out months", tuple(SuiteEntry(n, "solar", "test", d) for n, d in months.items())
    )
    register_suite(suite)
    yield suite
    unregister_suite(suite.name)


@pytest.fixture(scope="module")
def evaluated(two_months: Suite, tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("suite") / "root"
    result = solarchain_eval.evaluate("static", suite="two-months", seeds=SEEDS, episodes=EPISODES, out=out)
    return result, out


def test_the_builtin_suites_name_the_splits():
    heldout = get_suite("heldout")
    assert [e.name for e in heldout.entries] == [f"tmy-3sites-{m:02d}" for m in range(1, 13)]
    assert heldout.splits == ("test",) and {e.task for e in heldout.entries} == {"solar"}
    train = get_suite("train")
    assert [(e.name, e.split) for e in train.entries] == [("paper-2026-04", "train")]
    assert heldout.reference == ("random", "myopic")


def test_the_train_suite_runs_the_papers_protocol(published_dir, tmp_path):
    # the paper's seeds and episodes on the train entry: the paper's protocol id, and rliable's IQM of
    # Static's 90 raw scores (the leaderboard's fractional-weight IQM gives -23.4085 on them)
    result = solarchain_eval.evaluate("static", suite="train", out=tmp_path / "train")
    assert result.runs["paper-2026-04"].protocol_id == "89e17532f325"
    assert result.protocol["splits"] == ["train"] and result.protocol["protocol_ids"] == ["89e17532f325"]
    static = result.scores[result.scores.policy == "static"]["score"].to_numpy()
    assert len(static) == 90 and round(aggregate_iqm(static.reshape(-1, 1)), 4) == -23.4117


def test_the_suite_root_holds_one_run_per_entry_and_its_files_last(evaluated):
    result, out = evaluated
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [*MONTHS_NAMES, SUITE_SCORES_FILE, PROFILE_FILE, SUITE_METADATA_FILE]
    )
    meta = json.loads((out / SUITE_METADATA_FILE).read_text())
    assert meta["suite"] == "two-months" and meta["reference"] == ["random", "myopic"]
    for name, digest in meta["sha256"].items():
        assert sha256_file(out / name) == digest, name
    assert set(meta["sha256"]) == {SUITE_SCORES_FILE, PROFILE_FILE, "m01/run_metadata.json", "m07/run_metadata.json"}
    assert [(e["name"], e["split"], e["protocol_id"]) for e in meta["entries"]] == [
        (n, "test", result.runs[n].protocol_id) for n in MONTHS_NAMES
    ]
    # two months, two datasets: the run protocols differ by their dataset sha256s
    assert result.runs["m01"].protocol["dataset_sha256"] != result.runs["m07"].protocol["dataset_sha256"]
    assert len({e["protocol_id"] for e in meta["entries"]}) == 2
    assert meta["protocol"] == result.protocol
    assert meta["protocol"]["protocol_ids"] == sorted(e["protocol_id"] for e in meta["entries"])
    assert meta["protocol"]["splits"] == ["test"] and meta["protocol"]["score"] == ["cumulative_reward"]
    assert meta["protocol_id"] == sha256_text(canonical_json(meta["protocol"]))[:12] == result.protocol_id
    assert (out / PROFILE_FILE).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


MONTHS_NAMES = [f"m{m:02d}" for m in MONTHS]


def test_scores_are_normalised_on_each_entrys_own_baselines(evaluated):
    result, out = evaluated
    scores = read_csv_exact(out / SUITE_SCORES_FILE)
    assert len(scores) == 2 * 3 * len(SEEDS) * EPISODES  # entries x (static, random, myopic) x episodes
    for name in MONTHS_NAMES:
        metrics = read_csv_exact(out / name / "metrics.csv")
        low = metrics.loc[metrics.policy == "random", "cumulative_reward"].mean()
        high = metrics.loc[metrics.policy == "myopic", "cumulative_reward"].mean()
        rows = scores[(scores.entry == name) & (scores.policy == "static")].sort_values("episode")
        raw = metrics[metrics.policy == "static"].sort_values("episode")["cumulative_reward"].to_numpy()
        assert rows["score"].to_numpy() == pytest.approx(raw)
        assert rows["normalised"].to_numpy() == pytest.approx((raw - low) / (high - low))
        means = scores[scores.entry == name].groupby("policy")["normalised"].mean()
        assert means["random"] == pytest.approx(0.0, abs=1e-12) and means["myopic"] == pytest.approx(1.0)
    static = scores[scores.policy == "static"].pivot(
        index=["run_seed", "episode"], columns="entry", values="normalised"
    )
    row = result.aggregates.set_index("policy").loc["static"]
    assert row["iqm"] == pytest.approx(aggregate_iqm(static.to_numpy()))
    assert row["mean"] == pytest.approx(static.to_numpy().mean())
    assert row["iqm_low"] <= row["iqm"] <= row["iqm_high"]
    assert set(result.improvement["policy"]) == {"static", "random", "myopic"}


def test_suite_evaluate_equals_evaluate_per_entry(evaluated, months, tmp_path):
    result, out = evaluated
    for name, data in months.items():
        alone = solarchain_eval.evaluate(
            ["static", "random", "myopic"], data=data, seeds=SEEDS, episodes=EPISODES, out=tmp_path / name
        )
        suite_run = read_csv_exact(out / name / "metrics.csv")
        pd.testing.assert_frame_equal(suite_run, read_csv_exact(tmp_path / name / "metrics.csv"))
        assert alone.protocol_id == result.runs[name].protocol_id


def test_the_command_line_prints_per_entry_and_aggregate_scores(two_months, tmp_path):
    out = tmp_path / "cli"
    args = ["evaluate", "--suite", "two-months", "--policies", "static", "--seeds", "20260511", "--episodes", "2"]
    done = runner.invoke(app, [*args, "--out", str(out)])
    assert done.exit_code == 0, done.output
    assert "m01" in done.output and "IQM" in done.output and "optimality gap" in done.output
    meta = json.loads((out / SUITE_METADATA_FILE).read_text())
    assert f"suite protocol {meta['protocol_id']}" in done.output
    static = next(r for r in meta["aggregates"] if r["policy"] == "static")
    assert f"{static['iqm']:.3f} [{static['iqm_low']:.3f}, {static['iqm_high']:.3f}]" in done.output
    again = runner.invoke(app, [*args, "--out", str(out)])  # a finished root is not written over
    assert again.exit_code == 2 and "already holds" in again.output


def test_a_bad_suite_name_fails_in_one_line_and_writes_nothing(two_months, tmp_path):
    out = tmp_path / "never"
    done = runner.invoke(app, ["evaluate", "--suite", "nope", "--out", str(out)])
    assert done.exit_code == 2
    assert done.output.strip().splitlines() == [
        "error: unknown suite 'nope' (available: heldout, train, paper-early, paper-late, paper-cities, two-months)"
    ]
    assert not out.exists()
    with pytest.raises(UnknownSuiteError, match="unknown suite 'nope'"):
        solarchain_eval.evaluate("static", suite="nope", out=out)
    assert not out.exists()


def test_a_suite_refuses_data_and_task(two_months, tmp_path):
    done = runner.invoke(
        app, ["evaluate", "--suite", "two-months", "--data", str(tmp_path), "--out", str(tmp_path / "x")]
    )
    assert done.exit_code == 2 and "give neither --data nor --task" in done.output
    with pytest.raises(SuiteError, match="give neither data= nor task="):
        solarchain_eval.evaluate("static", suite="two-months", data=tmp_path)
    assert not (tmp_path / "x").exists()


def test_equal_reference_means_and_uneven_episodes_are_refused():
    metrics = pd.DataFrame(
        {"policy": ["random", "myopic"], "run_seed": [1, 1], "episode": [0, 0], "cumulative_reward": [-3.0, -3.0]}
    )
    entry = SuiteEntry("a", "solar", "test", "unused")
    with pytest.raises(SuiteScoreError, match="entry 'a': myopic and random have the same mean cumulative_reward"):
        entry_scores(entry, metrics, Suite("s", "", (entry,)))
    scores = pd.DataFrame(
        {"entry": ["a"] * 4, "policy": ["x", "x", "y", "y"], "run_seed": [1, 1, 1, 1], "episode": [0, 1, 0, 1]}
    )
    scores["normalised"] = [0.1, 0.2, 0.3, np.nan]
    with pytest.raises(SuiteScoreError, match="policy 'y': the entries of the suite ran different episodes"):
        matrices(scores)


AGENT = """
class Const:
    def act(self, observation):
        return [0.3, 0.7, 0.05]
"""


def test_every_door_runs_a_suite(two_months, tmp_path):
    agent_file = tmp_path / "const_agent.py"
    agent_file.write_text(AGENT)
    common = dict(suite="two-months", seeds=SEEDS, episodes=1)
    isolated = solarchain_eval.evaluate(f"const={agent_file}:Const", isolate=True, out=tmp_path / "iso", **common)
    in_process = solarchain_eval.evaluate(lambda obs: [0.3, 0.7, 0.05], name="const", out=tmp_path / "obj", **common)
    for name in MONTHS_NAMES:
        assert isolated.runs[name].access == {"const": "isolated", "random": "in-process", "myopic": "in-process"}
        assert in_process.runs[name].access["const"] == "in-process"
    pd.testing.assert_frame_equal(isolated.scores, in_process.scores)
    assert isolated.protocol_id == in_process.protocol_id
    assert list(dict.fromkeys(isolated.scores["policy"])) == ["const", "random", "myopic"]
