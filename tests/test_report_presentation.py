"""Report presentation: captions say only what is drawn."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from report_fixtures import RUN_SEEDS, make_paper_root, write_paper_metadata
from solarchain_eval.report import ReportOptions, build_report
from solarchain_eval.report.figures import FigureFile

OPTIONS = ReportOptions(n_resamples=200)
TRAJECTORIES = ("reward_trajectory", "liquidity_trajectories")


def one_seed_root(root: Path) -> Path:
    """The synthetic paper root cut down to its first run seed (every file, consistently)."""
    make_paper_root(root)
    keep = RUN_SEEDS[0]
    for folder in (root / "combined").iterdir():
        for name in ("metrics.csv", "actions.csv", "city_hour_policy.csv"):
            frame = pd.read_csv(folder / name)
            frame[frame["run_seed"] == keep].to_csv(folder / name, index=False)
        logs = folder / "agentic_logs.jsonl"
        if logs.exists():
            rows = [
                line for line in logs.read_text(encoding="utf-8").splitlines() if json.loads(line)["run_seed"] == keep
            ]
            logs.write_text("".join(r + "\n" for r in rows), encoding="utf-8")
    return write_paper_metadata(root)  # the cut files are this root's run, as the grid would record it


def captions(report) -> dict[str, str]:
    return {f.key: f.caption for f in report.figures if isinstance(f, FigureFile)}


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    two = build_report(make_paper_root(tmp_path_factory.mktemp("two-seeds")), options=OPTIONS)
    one = build_report(one_seed_root(tmp_path_factory.mktemp("one-seed")), options=OPTIONS)
    return two, one


def test_trajectory_captions_promise_bands_only_when_drawn(reports):
    two, one = (captions(r) for r in reports)
    for key in TRAJECTORIES:
        assert f"95% Student-t bands across the {len(RUN_SEEDS)} run seeds" in two[key], two[key]
        assert "band" in one[key] and "Student-t" not in one[key] and "95%" not in one[key], one[key]
        assert "no confidence band (1 run seed" in one[key], one[key]
