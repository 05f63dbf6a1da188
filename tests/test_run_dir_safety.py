"""A run directory is one whole run or it is refused: refusals, --overwrite, the lock, kills at
every publication step, concurrent writers, and ``report``'s verification of the sha256s."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.evaluation.rundir import (
    KILL_AT_ENV,
    KILL_POINTS,
    RunDirError,
    RunDirWriter,
    lock_path,
    verify_run_dir,
)
from solarchain_eval.report import ReportDataError, load_report_data

CLI = [sys.executable, "-c", "from solarchain_eval.cli import main; main()"]
RUN_FILES = {"metrics.csv", "actions.csv", "city_hour_policy.csv", "summary.json", "run_metadata.json"}


def evaluate_args(data: Path, out: Path, *extra: str, seeds: str = "5") -> list[str]:
    return [
        "evaluate",
        "--data",
        str(data),
        "--policies",
        "static",
        "--seeds",
        seeds,
        "--episodes",
        "1",
        "--out",
        str(out),
        *extra,
    ]


def invoke(args: list[str]):
    return CliRunner().invoke(app, args, catch_exceptions=False)


def run_cli(args: list[str], **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=300, env={**os.environ, **env})


def assert_whole_run(out: Path, seed: int) -> None:
    """``out`` is one complete run of run seed ``seed``: its files, all vouched for."""
    assert {p.name for p in out.iterdir()} == RUN_FILES
    assert verify_run_dir(out) == []
    assert json.loads((out / "run_metadata.json").read_text())["run_seeds"] == [seed]
    assert set((out / "metrics.csv").read_text().splitlines()[1].split(",")[2:3]) == {str(seed)}


def leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if p.name.startswith("."))


@pytest.fixture(scope="module")
def finished(tiny_dataset, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("finished") / "run"
    assert invoke(evaluate_args(tiny_dataset, out)).exit_code == 0
    return out


def test_existing_run_partial_run_unrelated_files_and_a_file_are_refused(tiny_dataset, finished, tmp_path):
    before = {p.name: p.read_bytes() for p in finished.iterdir()}
    cases = {finished: "holds a finished run"}
    partial = tmp_path / "partial"
    partial.mkdir()
    (partial / "metrics.csv").write_text("policy\n")
    cases[partial] = "holds a partial run (metrics.csv)"
    unrelated = tmp_path / "unrelated"
    unrelated.mkdir()
    (unrelated / "notes.txt").write_text("mine")
    cases[unrelated] = "holds unrelated files (notes.txt)"
    a_file = tmp_path / "a-file"
    a_file.write_text("x")
    cases[a_file] = "is an existing file, not a run directory"
    for out, message in cases.items():
        result = invoke(evaluate_args(tiny_dataset, out))
        assert result.exit_code == 2, result.output
        assert message in result.output and len(result.output.strip().splitlines()) == 1, result.output
    assert {p.name: p.read_bytes() for p in finished.iterdir()} == before  # nothing written
    assert (unrelated / "notes.txt").read_text() == "mine" and a_file.read_text() == "x"
    assert leftovers(tmp_path) == []


def test_unwritable_parent_is_refused_before_the_evaluation(tiny_dataset, tmp_path):
    if os.geteuid() == 0:  # root writes into a mode-500 folder; /proc/sys refuses even root
        result = invoke(evaluate_args(tiny_dataset, Path("/proc/sys/run")))
    else:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
        try:
            result = invoke(evaluate_args(tiny_dataset, locked / "run"))
        finally:
            locked.chmod(0o700)
    assert result.exit_code == 2 and "is not writable" in result.output


def test_unwritable_parent_is_refused_by_the_writer(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != tmp_path)  # as if tmp_path were read-only
    with pytest.raises(RunDirError, match=f"the folder {tmp_path} is not writable"):
        RunDirWriter(tmp_path / "run").__enter__()
    assert not lock_path(tmp_path / "run").exists()


def test_overwrite_replaces_the_whole_directory(tiny_dataset, tmp_path):
    out = tmp_path / "run"
    agentic = evaluate_args(tiny_dataset, out, "--agentic", "planner_auditor", "--policies", "myopic")
    assert invoke(agentic).exit_code == 0 and (out / "agentic_logs.jsonl").is_file()
    (out / "notes.txt").write_text("stale")
    result = invoke(evaluate_args(tiny_dataset, out, "--overwrite", seeds="6"))
    assert result.exit_code == 0, result.output
    assert_whole_run(out, 6)  # no agentic_logs.jsonl, no notes.txt from before
    assert leftovers(tmp_path) == []


def test_a_live_lock_refuses_a_second_writer_and_a_dead_ones_is_cleared(tiny_dataset, tmp_path):
    out = tmp_path / "run"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\nfrom solarchain_eval.evaluation.rundir import RunDirWriter\n"
            "w = RunDirWriter(sys.argv[1]).__enter__()\nprint('locked', flush=True)\ntime.sleep(60)",
            str(out),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        result = invoke(evaluate_args(tiny_dataset, out))
        assert result.exit_code == 2 and f"is being written by another run (pid {holder.pid})" in result.output
    finally:
        holder.kill()
        holder.wait()
    assert lock_path(out).exists() and leftovers(tmp_path) != [lock_path(out).name]  # its staging folder too
    # the writer died: its lock no longer counts, whatever pid the file names, and its staging is removed
    lock_path(out).write_text(json.dumps({"pid": os.getpid(), "started": 0}))  # a live (reused) pid
    assert invoke(evaluate_args(tiny_dataset, out)).exit_code == 0
    assert_whole_run(out, 5)
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("point", KILL_POINTS)
def test_a_kill_at_any_publication_step_leaves_the_old_run_or_none(tiny_dataset, tmp_path, point):
    out = tmp_path / "run"
    assert run_cli(evaluate_args(tiny_dataset, out)).returncode == 0
    killed = run_cli(evaluate_args(tiny_dataset, out, "--overwrite", seeds="6"), **{KILL_AT_ENV: point})
    assert killed.returncode == -9, killed.stderr
    if point == "old-moved":
        assert not out.exists()  # between the two renames: no run at all
    elif point == "published":
        assert_whole_run(out, 6)
    else:
        assert_whole_run(out, 5)
    assert any(name.startswith(".run.") for name in leftovers(tmp_path)) or point == "published"
    again = run_cli(evaluate_args(tiny_dataset, out, "--overwrite", seeds="7"))
    assert again.returncode == 0, again.stderr
    assert_whole_run(out, 7)
    assert leftovers(tmp_path) == []  # no orphan staging, old folder, *.partial or lock survives


def test_a_kill_during_the_evaluation_leaves_the_previous_run(tiny_dataset, tmp_path):
    out = tmp_path / "run"
    assert run_cli(evaluate_args(tiny_dataset, out)).returncode == 0
    proc = subprocess.Popen([*CLI, *evaluate_args(tiny_dataset, out, "--overwrite", seeds="6")])
    deadline = time.monotonic() + 60
    while not any(n.startswith(".run.staging-") for n in leftovers(tmp_path)) and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.kill()
    proc.wait()
    assert_whole_run(out, 5)


def test_concurrent_writers_leave_one_whole_run(tiny_dataset, tmp_path):
    for trial in range(3):
        out = tmp_path / f"run{trial}"
        procs = [
            subprocess.Popen([*CLI, *evaluate_args(tiny_dataset, out, seeds=str(s))], stderr=subprocess.PIPE, text=True)
            for s in (5, 6)
        ]
        codes = [p.wait(timeout=300) for p in procs]
        errors = [p.stderr.read() for p in procs]
        assert sorted(codes) == [0, 2], errors  # exactly one wins; the other is refused
        loser = errors[codes.index(2)]
        assert "being written by another run" in loser or "holds a finished run" in loser
        winner = (5, 6)[codes.index(0)]
        assert_whole_run(out, winner)
    assert leftovers(tmp_path) == []


def test_report_verifies_the_recorded_sha256s(tiny_dataset, finished, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(finished, run)
    assert load_report_data(run).unverified == []
    (run / "metrics.csv").write_text((run / "metrics.csv").read_text().replace(",5,", ",5,", 1) + "\n")
    with pytest.raises(ReportDataError, match=r"metrics\.csv does not match the sha256 in run_metadata\.json"):
        load_report_data(run)
    shutil.copy(finished / "metrics.csv", run / "metrics.csv")
    (run / "agentic_logs.jsonl").write_text("")  # a left-over of another run
    with pytest.raises(ReportDataError, match=r"agentic_logs\.jsonl is not vouched for"):
        load_report_data(run)
    (run / "agentic_logs.jsonl").unlink()
    (run / "run_metadata.json").unlink()
    with pytest.raises(ReportDataError, match="has no run_metadata.json"):
        load_report_data(run)
    data = load_report_data(run, allow_unverified=True)
    assert data.unverified and len(data.metrics) == 1
    result = invoke(["report", str(run), "--no-figures", "--format", "md", "--resamples", "100", "--allow-unverified"])
    assert result.exit_code == 0 and "UNVERIFIED INPUT" in result.output
    refused = invoke(["report", str(run), "--no-figures", "--format", "md"])
    assert refused.exit_code == 2 and "--allow-unverified" in refused.output


def test_report_shows_no_credentials_of_an_old_verbatim_command(finished, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(finished, run)
    meta = json.loads((run / "run_metadata.json").read_text())
    meta["command"] = [
        "solarchain-eval",
        "evaluate",
        "--llm-base-url",
        "https://u:pw-SECRET@h/v1?token=tok-SECRET",
        "--api-key",
        "sk-SECRET",
    ]
    (run / "run_metadata.json").write_text(json.dumps(meta))
    result = invoke(["report", str(run), "--no-figures", "--format", "html", "--resamples", "100"])
    assert result.exit_code == 0, result.output
    html = (run / "report" / "index.html").read_text()
    assert "SECRET" not in html and "https://[redacted]@h/v1?token=[redacted]" in html


def test_command_lines_are_redacted_and_redaction_is_idempotent(monkeypatch):
    from solarchain_eval.common.redaction import redact_command

    monkeypatch.setenv("OPENAI_API_KEY", "sk-env-key-123")
    argv = [
        "solarchain-eval",
        "evaluate",
        "--llm-base-url",
        "http://u:pw@h:8080/v1?token=t1&x=2#f",
        "--api-key",
        "k1",
        "--hf-token=t2",
        "--llm-max-output-tokens",
        "512",
        "--note",
        "key is sk-env-key-123",
    ]
    expected = [
        "solarchain-eval",
        "evaluate",
        "--llm-base-url",
        "http://[redacted]@h:8080/v1?token=[redacted]&x=[redacted]#[redacted]",
        "--api-key",
        "[redacted]",
        "--hf-token=[redacted]",
        "--llm-max-output-tokens",
        "512",
        "--note",
        "key is [redacted]",
    ]
    assert redact_command(argv) == expected
    assert redact_command(expected) == expected
