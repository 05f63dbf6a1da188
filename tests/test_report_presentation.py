"""Report presentation: captions say only what is drawn."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from report_fixtures import RUN_SEEDS, make_paper_root, write_paper_metadata
from solarchain_eval.report import ReportOptions, build_report
from solarchain_eval.report.paper.figures import FigureFile

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


# ----------------------------------------------------------------------------- one policy order


ONE_ORDER = ["Static", "Random", "Myopic", "PPO", "SAC", "DQN"]


def test_every_table_lists_policies_in_the_one_order(reports):
    two, _ = reports
    checked = 0
    for table in two.tables:
        if not hasattr(table, "data") or "policy" not in table.data.columns:
            continue
        frame = table.data
        groups = [frame] if "setting" not in frame.columns else [g for _, g in frame.groupby("setting", sort=False)]
        for group in groups:
            by_comparison = "comparison" in group.columns
            for rows in [g for _, g in group.groupby("comparison", sort=False)] if by_comparison else [group]:
                shown = [p for p in rows["policy"] if p in ONE_ORDER]
                assert shown == sorted(shown, key=ONE_ORDER.index), (table.key, list(rows["policy"]))
                checked += 1
    assert checked >= 8  # the main, detail, agentic, delta and action tables all list policies


# ----------------------------------------------------------------------------- small samples


def test_small_samples_carry_a_visible_caveat(reports):
    from solarchain_eval.report.statistics import SampleSize
    from solarchain_eval.report.table_model import SMALL_SAMPLE_CAVEAT, basis_sentence, to_html, to_markdown

    assert SMALL_SAMPLE_CAVEAT not in basis_sentence([SampleSize(90, 30, 21)], "rollouts")  # the paper's protocol
    tiny = basis_sentence([SampleSize(90, 30, 21), SampleSize(2, 2, 2)], "rollouts")
    assert f"{SMALL_SAMPLE_CAVEAT}: as few as 2 distinct start day(s)" in tiny
    two, _ = reports  # the synthetic root: 3 distinct start days per row
    table = next(t for t in two.tables if getattr(t, "key", "") == "main_performance")
    assert "as few as 3 distinct start day(s)" in table.basis
    assert '<p class="caveat">Small sample: as few as 3' in to_html(table)
    assert "**Small sample: as few as 3" in to_markdown(table)


# ----------------------------------------------------------------------------- run metadata


def test_run_metadata_shows_shared_fields_once_and_no_json():
    from types import SimpleNamespace

    from solarchain_eval.report.paper.html import _run_metadata

    command = ["solarchain-eval", "paper", "--out", "ROOT", "--preset", "smoke"]
    units = {
        f"{setting}_seed{seed}": {
            "command": command,
            "git_commit": "abc123",
            "setting": setting,
            "policies": ["static", "ppo"],
            "run_seeds": [seed],
            "episodes": 2,
            "episode_seed_protocol": {"kind": "paper", "offset": 0},
        }
        for setting in ("main", "no_physics")
        for seed in (11, 12)
    }
    html = _run_metadata(SimpleNamespace(kind="paper", metadata={}, unit_metadata=units))
    assert html.count("solarchain-eval paper --out ROOT --preset smoke") == 1
    assert html.count("abc123") == 1
    assert "<th>setting</th>" in html and "<th>run_seeds</th>" in html and "<th>command</th>" not in html
    assert "kind=paper, offset=0" in html and "static ppo" in html
    for json_mark in ('{"', '["', "[1", '": '):
        assert json_mark not in html, json_mark
