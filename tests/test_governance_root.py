"""``run_governance`` from Python leaves the leaderboard root the ``governance`` command leaves."""

from __future__ import annotations

import json

import pandas as pd
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.experiments.governance import (
    GOVERNANCE_METADATA_FILE,
    Combination,
    GovernanceSpec,
    run_governance,
)
from solarchain_eval.governance.factory import AgenticOptions
from solarchain_eval.report import build_report
from solarchain_eval.report.governance.leaderboard import governance_leaderboard, write_governance_leaderboard

AUDITORS = ("rule", "approve-only")


def _files(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and not p.name.startswith("."))


def _spec(tiny_dataset):
    combinations = [Combination("rule", a, AgenticOptions(planner="rule", auditor=a)) for a in AUDITORS]
    return GovernanceSpec(
        policies=["random"], combinations=combinations, run_seeds=(3,), episodes=1, data_dir=tiny_dataset
    )


def test_run_governance_from_python_leaves_the_commands_root(tiny_dataset, tmp_path):
    out = tmp_path / "cli"
    args = ["governance", "--data", str(tiny_dataset), "--policies", "random", "--seeds", "3", "--episodes", "1"]
    args += ["--planner", "rule", "--auditors", ",".join(AUDITORS), "--resamples", "100", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output

    root = tmp_path / "python"

    def tables(runs, where):
        return write_governance_leaderboard(governance_leaderboard(runs, resamples=100), where)

    runs = run_governance(_spec(tiny_dataset), root, tables=tables, command=["my-script"])

    assert _files(root) == _files(out)
    mine = json.loads((root / GOVERNANCE_METADATA_FILE).read_text())
    theirs = json.loads((out / GOVERNANCE_METADATA_FILE).read_text())
    assert list(mine) == list(theirs)
    assert mine["complete"] is True and mine["command"] == ["my-script"]
    for key in ("unsafe_threshold", "settings", "policies", "combinations"):
        assert mine[key] == theirs[key], key
    assert mine["policies"] == ["random"]
    # the metadata hashes every table and figure the writer made, as written
    tables_written = [f for f in _files(root) if not f.startswith("runs/") and f != GOVERNANCE_METADATA_FILE]
    assert sorted(mine["files"]) == tables_written
    assert all(mine["files"][name] == sha256_file(root / name) for name in tables_written)
    # the same combinations, the same audit figures as the command's board
    columns = ["planner", "auditor", "audit_rate", "precision", "recall", "delta_cost_per_step"]
    board = pd.read_csv(root / "leaderboard.csv")[columns].sort_values("auditor", ignore_index=True)
    expected = pd.read_csv(out / "leaderboard.csv")[columns].sort_values("auditor", ignore_index=True)
    pd.testing.assert_frame_equal(board, expected)
    # and the report reads a combination's run as it reads the command's
    assert [r.run_dir for r in runs] == [root / "runs" / "llm" / f"rule--{a}" for a in AUDITORS]
    report = build_report(runs[0].run_dir, tmp_path / "report", formats=("md",), figures=False)
    assert any(t.key == "governance_diagnostics" for t in report.tables)


def test_without_a_tables_writer_the_root_is_still_finished(tiny_dataset, tmp_path):
    root = tmp_path / "board"
    run_governance(_spec(tiny_dataset), root, command=["my-script"])
    metadata = json.loads((root / GOVERNANCE_METADATA_FILE).read_text())
    assert metadata["complete"] is True and metadata["files"] == {}
    assert [c["auditor"] for c in metadata["combinations"]] == list(AUDITORS)
    assert {f.split("/")[0] for f in _files(root)} == {"runs", GOVERNANCE_METADATA_FILE}  # no tables written
