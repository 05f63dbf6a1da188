"""verify and leaderboard under a forger (docs/security.md): the rollout set of a run whose
checksums were recomputed, tarball limits and vouching checked before anything is unpacked,
and a board folder inside an input."""

from __future__ import annotations

import csv
import io
import json
import shutil
import tarfile
from pathlib import Path

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.evaluation.fingerprint import protocol_fingerprint, protocol_id
from solarchain_eval.evaluation.verify_checks import rollout_set_problem
from submission_tarball import pack

RUN_SEED = 5


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def pristine(tiny_dataset, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "run"
    result = invoke("evaluate", "--data", tiny_dataset, "--policies", "static,myopic",
                    "--seeds", RUN_SEED, "--episodes", 2, "--out", out)  # fmt: skip
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture
def run(pristine, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(pristine, copy)
    return copy


def rewrite_rows(run: Path, edit) -> None:
    """Apply ``edit(header, rows) -> rows`` to metrics.csv, then re-vouch for it and its row count."""
    path = run / "metrics.csv"
    header, *rows = list(csv.reader(io.StringIO(path.read_text())))
    rows = edit(header, rows)
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows([header, *rows])
    path.write_text(buffer.getvalue())
    meta = json.loads((run / "run_metadata.json").read_text())
    meta["files"]["metrics.csv"] = sha256_file(path)
    meta["rows"]["metrics"] = len(rows)
    (run / "run_metadata.json").write_text(json.dumps(meta))


def row_of(header, rows, policy, episode):
    return next(r for r in rows if r[header.index("policy")] == policy and r[header.index("episode")] == str(episode))


def verify_lines(run: Path, *extra) -> tuple[int, list[str]]:
    result = invoke("verify", run, "--episodes", 1, *extra)
    return result.exit_code, [line for line in result.output.splitlines() if line.strip()]


def test_the_untouched_run_verifies(run):
    code, lines = verify_lines(run)
    assert code == 0 and lines[:2] == ["static: verified (1 episode)", "myopic: verified (1 episode)"], lines


def test_a_deleted_row_is_caught_before_any_rerun(run):
    # --seed 0 draws episode 1; the deleted row is episode 0's, which a re-run alone never looks at.
    rewrite_rows(run, lambda h, rows: [r for r in rows if r is not row_of(h, rows, "myopic", 0)])
    code, lines = verify_lines(run, "--seed", 0)
    assert code == 1
    assert lines[0] == (
        "rollouts: metrics.csv: policy 'myopic' holds 1 of the 2 rollouts its protocol promises "
        f"(run seeds [{RUN_SEED}] × 2 episodes); missing: run seed {RUN_SEED}, episode 0"
    )
    assert not any("verified" in line for line in lines)


def test_a_forged_duplicate_placed_before_the_real_row_is_caught(run):
    def forge(header, rows):
        real = row_of(header, rows, "static", 0)
        forged = list(real)
        forged[header.index("cumulative_reward")] = "1000000.0"
        return [forged if r is real else r for r in rows] + [real]

    rewrite_rows(run, forge)
    code, lines = verify_lines(run, "--episodes", 100)
    assert code == 1
    assert (
        lines[0]
        == f"rollouts: metrics.csv: rollout (policy 'static', run seed {RUN_SEED}, episode 0) appears more than once"
    )


def test_an_extra_episode_row_is_caught(run):
    def add(header, rows):
        extra = list(row_of(header, rows, "static", 1))
        extra[header.index("episode")] = "2"
        return [*rows, extra]

    rewrite_rows(run, add)
    code, lines = verify_lines(run)
    assert code == 1
    assert lines[0] == (
        "rollouts: metrics.csv: policy 'static' holds rollout (run seed 5, episode 2) outside its protocol "
        f"(run seeds [{RUN_SEED}] × 2 episodes)"
    )


def test_episodes_forged_in_metadata_and_fingerprint_is_caught(run):
    meta = json.loads((run / "run_metadata.json").read_text())
    meta["episodes"] = 1
    recorded = meta["protocol"]
    meta["protocol"] = protocol_fingerprint(
        dataset_sha256=meta["dataset"]["files"],
        run_seeds=meta["run_seeds"],
        episodes=1,
        episode_seed_rule=recorded["episode_seed_rule"],
        setting=meta["setting"],
        config=BenchmarkConfig.model_validate(meta["config"]),
        action_modes=recorded["action_modes"],
    )
    meta["protocol_id"] = protocol_id(meta["protocol"])
    (run / "run_metadata.json").write_text(json.dumps(meta))
    code, lines = verify_lines(run)
    assert code == 1
    assert lines[0] == (
        "rollouts: metrics.csv: policy 'myopic' holds rollout (run seed 5, episode 1) outside its protocol "
        f"(run seeds [{RUN_SEED}] × 1 episodes)"
    )
    assert lines[-1].startswith("checksums match (") and "inconsistent" not in lines[-1]  # only the rollouts tell
    board = invoke("leaderboard", run, "--out", run.parent / "board")
    assert board.exit_code == 2 and "outside its protocol" in board.output
    assert not (run.parent / "board").exists()


def test_a_row_count_that_differs_from_the_metadata_is_named(run):
    meta = json.loads((run / "run_metadata.json").read_text())
    meta["rows"]["metrics"] = 5
    (run / "run_metadata.json").write_text(json.dumps(meta))
    code, lines = verify_lines(run)
    assert code == 1 and lines[0] == "rollouts: metrics.csv holds 4 rows; run_metadata.json records 5"


def test_the_rollout_rule_is_one_for_verify_and_the_board():
    keys = [("a", 1, 0), ("a", 1, 1), ("b", 1, 0), ("b", 1, 1)]
    assert rollout_set_problem(keys, ["a", "b"], [1], 2) is None
    assert "appears more than once" in rollout_set_problem([*keys, ("a", 1, 0)], ["a", "b"], [1], 2)
    assert rollout_set_problem(keys, ["a"], [1], 2) == "policy 'b' has rows but is not one of the run's policies (a)"
    assert "missing: run seed 2, episode 0" in rollout_set_problem(keys, ["a", "b"], [1, 2], 2)


def test_the_board_refuses_an_out_folder_inside_an_input(run):
    result = invoke("leaderboard", run, "--out", run / "board")
    assert result.exit_code == 2
    assert f"--out {run / 'board'} lies inside the input {run}" in " ".join(result.output.split())
    assert not (run / "board").exists()


@pytest.fixture
def no_extraction(monkeypatch):
    """Fails the test if anything is unpacked."""
    calls = []
    real = tarfile.TarFile.extractall
    monkeypatch.setattr(tarfile.TarFile, "extractall", lambda self, *a, **k: calls.append(a) or real(self, *a, **k))
    return calls


def test_a_tarball_past_the_size_limit_is_refused_before_unpacking(run, tmp_path, no_extraction):
    zeros = b"\0" * (3 * 2**20)
    tarball = pack(tmp_path / "big.tar.gz", run, {"zeros.bin": zeros})
    assert tarball.stat().st_size < 100_000  # small to send, large to unpack
    result = invoke("leaderboard", tarball, "--out", tmp_path / "board", "--max-unpacked-mb", 2)
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert (
        f"{tarball}: unpacks to more than 2 MB (submission/zeros.bin alone is 3.0 MB); refused before unpacking" in text
    )
    assert "--max-unpacked-mb" in text
    assert no_extraction == [] and not (tmp_path / "board").exists()


def test_a_tarball_with_too_many_members_is_refused(run, tmp_path, no_extraction):
    tarball = pack(tmp_path / "many.tar.gz", run)
    result = invoke("leaderboard", tarball, "--out", tmp_path / "board", "--max-members", 3)
    assert result.exit_code == 2 and "holds more than 3 members" in result.output
    assert no_extraction == []


def test_a_tarball_file_nothing_vouches_for_is_refused(run, tmp_path, no_extraction):
    tarball = pack(tmp_path / "stray.tar.gz", run, {"zeros.bin": b"\0" * 1000})
    result = invoke("leaderboard", tarball, "--out", tmp_path / "board")
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert f"{tarball}: submission/zeros.bin is not vouched for by the run's metadata; refused before unpacking" in text
    assert no_extraction == []
    honest = pack(tmp_path / "honest.tar.gz", run)
    ok = invoke("leaderboard", honest, "--out", tmp_path / "board")
    assert ok.exit_code == 0, ok.output
    assert len(no_extraction) == 1


def test_a_tarball_with_a_link_is_refused(run, tmp_path, no_extraction):
    tarball = tmp_path / "link.tar.gz"
    with tarfile.open(tarball, "w:gz") as archive:
        archive.add(run, arcname="submission")
        link = tarfile.TarInfo("submission/notes.txt")
        link.type, link.linkname = tarfile.SYMTYPE, "/etc/passwd"
        archive.addfile(link)
    result = invoke("leaderboard", tarball, "--out", tmp_path / "board")
    assert result.exit_code == 2
    assert "submission/notes.txt is a link or special file" in " ".join(result.output.split())
    assert no_extraction == []
