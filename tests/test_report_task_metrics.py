"""A metric declared once shows in the report and on the board: the toy task (tests/toy_task.py)
with one more MetricSpec, run directories of it, its report tables by dimension and its board;
boards never mix tasks; the solar market's board and report keep the paper's layout."""

from __future__ import annotations

import hashlib
import json
import statistics
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.evaluation.fingerprint import protocol_fingerprint, protocol_id
from solarchain_eval.evaluation.run_metadata import RunMetadata
from solarchain_eval.records_schema import Column
from solarchain_eval.report import build_report
from solarchain_eval.report.leaderboard import make_leaderboards
from solarchain_eval.report.leaderboard.inputs import LeaderboardError, open_inputs
from solarchain_eval.report.leaderboard.ranking import COLUMNS, board_layout, build_leaderboard, build_leaderboards
from solarchain_eval.report.leaderboard.render import display_columns
from solarchain_eval.report.options import LeaderboardOptions, ReportDataError, ReportOptions
from solarchain_eval.report.task_summary import summary_metrics
from solarchain_eval.tasks.base import MetricSpec
from solarchain_eval.tasks.registry import UnknownTaskError, get_task, register_task, unregister_task
from toy_task import STEPS, ToyTask

OPTIONS = LeaderboardOptions(n_resamples=200, formats=("csv", "md", "html"))
REPORT_OPTIONS = ReportOptions(n_resamples=200)
RUN_SEED, EPISODES = 7, 4
#: The one declaration the test adds: a utility metric with its own unit.
FILL = MetricSpec(Column("fill_per_hour", "units/h", "mean stock shipped to demand per hour"), "utility", "higher")


class ToyWithFill(ToyTask):
    """The toy task with :data:`FILL` declared (and computed) beside its three metrics."""

    metrics = (*ToyTask.metrics, FILL)

    def episode_metrics(self, steps, env):
        return {**super().episode_metrics(steps, env), "fill_per_hour": float(np.mean(steps["filled"]))}


#: The policies of the toy runs: the task's baseline and two fixed-action agents.
POLICIES = {
    "steady": lambda obs: np.float32([0.3, 0.5, 0.2]),
    "eager": lambda obs: np.float32([0.9, 0.9, 0.0]),
    "timid": lambda obs: np.float32([0.1, 0.2, 0.6]),
}


def _episode(task, act, seed: int) -> dict[str, float]:
    env = task.make_env(None, None)
    obs, _ = env.reset(seed=seed)
    steps: dict[str, list] = {field: [] for field in task.step_fields}
    for _ in range(STEPS):
        obs, _, _, _, info = env.step(act(obs))
        for field in task.step_fields:
            steps[field].append(info[field])
    return task.episode_metrics(steps, env)


def write_toy_run(out: Path, task, policies, setting: str = "main") -> Path:
    """A run directory of ``task`` as the records writers lay one out: metrics.csv and a complete
    run_metadata.json vouching for it, with the task and its protocol."""
    rows = []
    for policy in policies:
        for episode in range(EPISODES):
            seed = RUN_SEED + episode
            keys = {"policy": policy, "setting": setting, "run_seed": RUN_SEED, "episode": episode}
            # the toy market has no calendar: each episode is given a day of its own so the bootstrap has clusters
            keys |= {"episode_seed": seed, "start_hour": 24 * episode}
            rows.append(keys | _episode(task, POLICIES[policy], seed))
    out.mkdir(parents=True)
    pd.DataFrame(rows).to_csv(out / "metrics.csv", index=False)
    config = task.default_config()
    fingerprint = protocol_fingerprint(
        dataset_sha256={},
        run_seeds=[RUN_SEED],
        episodes=EPISODES,
        episode_seed_rule="paper",
        setting=setting,
        config=config,
        action_modes=dict.fromkeys(policies, "continuous"),
        task=task,
    )
    RunMetadata(
        complete=True,
        files={"metrics.csv": hashlib.sha256((out / "metrics.csv").read_bytes()).hexdigest()},
        command=["test"],
        started_at="2026-01-01T00:00:00+00:00",
        wall_s=0.0,
        git_commit=None,
        package_versions={},
        setting=setting,
        task=task.name,
        policies=list(policies),
        policy_access=dict.fromkeys(policies, "in-process"),
        protocol=fingerprint,
        protocol_id=protocol_id(fingerprint),
        run_seeds=[RUN_SEED],
        episodes=EPISODES,
        episode_seed_protocol="paper",
        rows={"metrics": len(rows), "actions": 0},
        dataset={"data_dir": "none", "files": {}},
        models={},
        config=task.config_record(config),
    ).write(out / "run_metadata.json")
    return out


@pytest.fixture()
def toy_task():
    """:class:`ToyWithFill` registered as ``toy-stock`` for the test (the one before it restored after)."""
    try:
        before = get_task("toy-stock")
    except UnknownTaskError:
        before = None
    task = ToyWithFill()
    register_task(task)
    yield task
    unregister_task("toy-stock")
    if before is not None:
        register_task(before)


@pytest.fixture()
def toy_run(toy_task, tmp_path) -> Path:
    return write_toy_run(tmp_path / "toy_run", toy_task, ("steady", "eager", "timid"))


def test_a_declared_metric_shows_in_the_report_with_its_unit_and_direction(toy_run, toy_task):
    outcome = build_report(toy_run, formats=("md", "tex", "csv", "html"), options=REPORT_OPTIONS, figures=False)
    keys = [t.key for t in outcome.tables]
    # one line instead of the paper's tables, then one table per template dimension
    assert keys[:6] == ["paper", "task_utility", "task_safety", "task_stability", "task_fairness", "task_auditability"]
    # then one contrast table per declared kind: a run of one setting has no contrast to draw
    assert keys[6:] == ["task_contrast_ablation", "task_contrast_governance"]
    skipped = {t.key: t.reason for t in outcome.tables if not hasattr(t, "data")}
    assert set(skipped) == {"paper", "task_fairness", "task_auditability", *keys[6:]}
    assert "the run has main" in skipped["task_contrast_ablation"]
    assert "no paper reference" in skipped["paper"]
    assert "declares no fairness metric" in skipped["task_fairness"]
    utility = (outcome.out_dir / "tables" / "task_utility.md").read_text(encoding="utf-8")
    assert "fill_per_hour (units/h) ↑" in utility and "total_reward (–) ↑" in utility
    assert "shortfall_units (units) ↓" in (outcome.out_dir / "tables" / "task_safety.md").read_text(encoding="utf-8")
    assert r"fill\_per\_hour (units/h) $\uparrow$" in (outcome.out_dir / "tables" / "task_utility.tex").read_text()
    # the cell is the mean ± sample std of the column the task computed
    metrics = pd.read_csv(toy_run / "metrics.csv")
    eager = metrics[metrics["policy"] == "eager"]["fill_per_hour"].tolist()
    table = next(t for t in outcome.tables if t.key == "task_utility")
    row = table.data[table.data["policy"] == "eager"].iloc[0]
    assert row["fill_per_hour_mean"] == pytest.approx(statistics.fmean(eager), abs=1e-12)
    assert row["fill_per_hour_std"] == pytest.approx(statistics.stdev(eager), abs=1e-12)
    assert row["fill_per_hour_low"] <= row["fill_per_hour_mean"] <= row["fill_per_hour_high"]
    # decimals by the column's magnitude: 3 for values between 1 and 100 (eager fills just over 1 unit/h)
    assert 1 <= max(metrics["fill_per_hour"]) < 100
    cell = f"{statistics.fmean(eager):.3f} ± {statistics.stdev(eager):.3f}"
    assert f"| main | eager | {EPISODES} |" in utility and cell in utility
    assert list(table.data["policy"]) == ["eager", "steady", "timid"]  # by name: no paper order for the toy
    page = (outcome.out_dir / "index.html").read_text(encoding="utf-8")
    assert "fill_per_hour (units/h) ↑" in page
    report_md = (outcome.out_dir / "report.md").read_text(encoding="utf-8")
    assert "Task: `toy-stock`." in report_md and "no paper reference" in report_md
    result = CliRunner().invoke(
        app, ["report", str(toy_run), "--resamples", "200", "--no-figures", "--against", "paper"]
    )
    assert result.exit_code == 2 and "no paper reference" in result.output
    with pytest.raises(ReportDataError, match="task 'toy-stock' has no paper reference"):
        build_report(toy_run, formats=("md",), options=REPORT_OPTIONS, figures=False, against="paper")


def test_a_declared_metric_shows_on_the_board_and_ranking_follows_the_declarations(toy_run, toy_task, tmp_path):
    with open_inputs([toy_run]) as sections:
        board = build_leaderboard(sections, OPTIONS)
    layout = board.layout
    assert (layout.task, layout.ranked.name, layout.baselines) == ("toy-stock", "total_reward", ("steady",))
    assert [m.name for m in layout.shown] == ["shortfall_units", "stock_swing", "fill_per_hour"]
    (section,) = board.sections
    metrics = pd.read_csv(toy_run / "metrics.csv")
    means = metrics.groupby("policy")["total_reward"].mean().sort_values(ascending=False)
    assert list(section.ranked["policy"]) == list(means.index)  # ranked by the first utility metric, higher first
    assert section.best_baseline == "steady"
    fill = metrics.groupby("policy")["fill_per_hour"].mean()
    for _, row in section.ranked.iterrows():
        assert row["fill_per_hour_mean"] == pytest.approx(fill[row["policy"]], abs=1e-12)
    outcome = make_leaderboards([toy_run], tmp_path / "board", OPTIONS)
    csv = pd.read_csv(outcome.files["leaderboard.csv"])
    assert "fill_per_hour_mean" in csv.columns and "total_reward_iqm" in csv.columns
    assert "cumulative_reward_mean" not in csv.columns
    md = outcome.files["leaderboard.md"].read_text(encoding="utf-8")
    assert "| fill_per_hour (units/h) ↑ |" in md and "| shortfall_units (units) ↓ |" in md
    assert "Mean total_reward (–) ↑ [95% CI]" in md and "- Task: `toy-stock`" in md
    assert "ranked per setting by mean total reward" in md and "best baseline (steady, by mean total reward)" in md
    assert "total_reward vs shortfall_units" in md  # the figure plots the ranked metric against a safety cost
    assert (
        "| 1 | steady | in-process |" in md and "| eager (user agent) |" in md
    )  # the task's baseline is no user agent
    shown = CliRunner().invoke(app, ["leaderboard", str(toy_run), "--out", str(tmp_path / "cli"), "--resamples", "200"])
    assert shown.exit_code == 0, shown.output
    assert "mean total_reward" in shown.output and (tmp_path / "cli" / "leaderboard.md").is_file()
    html = outcome.files["leaderboard.html"].read_text(encoding="utf-8")
    assert 'data-best="descending">fill_per_hour (units/h) ↑</th>' in html
    assert 'data-best="ascending">stock_swing (units) ↓</th>' in html


def test_a_board_never_mixes_tasks(toy_task, tmp_path):
    toy = write_toy_run(tmp_path / "toy", toy_task, ("steady", "eager"))
    # the same env id and protocol as the toy's: only the task tells the two boards apart
    other = type("OtherToy", (ToyTask,), {"name": "toy-other"})()
    register_task(other)
    try:
        second = write_toy_run(tmp_path / "other", other, ("steady",))
        with open_inputs([toy, second]) as sections:
            with pytest.raises(
                LeaderboardError, match=r"on task 'toy-stock' and .* on task 'toy-other'; a board ranks one task"
            ):
                build_leaderboard(sections, OPTIONS)
            boards = build_leaderboards(sections, LeaderboardOptions(n_resamples=200, split=True))
        assert [b.layout.task for b in boards] == ["toy-stock", "toy-other"]
        assert len({b.board_id for b in boards}) == 2
        result = CliRunner().invoke(app, ["leaderboard", str(toy), str(second), "--out", str(tmp_path / "b")])
        assert result.exit_code == 2 and "a board ranks one task" in result.output
        assert not (tmp_path / "b").exists()
    finally:
        unregister_task("toy-other")


def test_the_solar_board_keeps_the_papers_layout():
    assert summary_metrics(get_task("solar")) == {}  # the paper's tables cover every solar metric
    layout = board_layout("solar")
    assert layout.columns() == COLUMNS
    assert layout.baselines == ("static", "random", "myopic")
    headers = [c.header for c in display_columns(0.95, layout)]
    assert headers[5:] == [
        "Mean reward [95% CI]",
        "IQM reward [95% CI]",
        "P(> best baseline) [95% CI]",
        "Violation rate",
        "Artificial liquidity (MWh)",
        "Slippage",
        "Action jitter",
        "Fairness index",
    ]


def test_a_metric_declared_for_the_solar_market_joins_its_board_after_the_papers_columns():
    solar = get_task("solar")
    extra = MetricSpec(Column("peak_shortage", "MWh", "largest hourly shortage"), "safety", "lower")
    register_task(replace(solar, metrics=(*solar.metrics, extra)))
    try:
        layout = board_layout("solar")
        assert layout.columns() == (*COLUMNS[:-2], "peak_shortage_mean", *COLUMNS[-2:])
        # and the report gives it its dimension's table beside the paper's (which cover the other eleven)
        assert summary_metrics(get_task("solar")) == {"safety": (extra,)}
        assert [c.header for c in display_columns(0.95, layout)][-1] == "peak_shortage (MWh) ↓"
    finally:
        register_task(solar)


def _grid_root(root: Path, units: dict[str, Path]) -> Path:
    """A grid root laid out as ``paper`` lays one out: finished eval units, their rows combined per
    setting, and ``paper_metadata.json`` vouching for the combined files."""
    for name, run in units.items():
        unit = root / "units" / "eval" / name
        unit.parent.mkdir(parents=True, exist_ok=True)
        run.rename(unit)
        (unit / "DONE").write_text("done\n", encoding="utf-8")
    frames = [pd.read_csv(root / "units" / "eval" / name / "metrics.csv") for name in units]
    combined = root / "combined" / "main"
    combined.mkdir(parents=True)
    pd.concat(frames, ignore_index=True).to_csv(combined / "metrics.csv", index=False)
    digest = hashlib.sha256((combined / "metrics.csv").read_bytes()).hexdigest()
    (root / "paper_metadata.json").write_text(json.dumps({"combined_sha256": {"main": {"metrics.csv": digest}}}))
    return root


def test_a_grid_root_of_a_task_is_reported_and_ranked_by_its_declarations(toy_task, tmp_path):
    unit = write_toy_run(tmp_path / "u", toy_task, ("steady", "eager"))
    root = _grid_root(tmp_path / "root", {"main-s7": unit})
    outcome = build_report(root, formats=("md",), options=REPORT_OPTIONS, figures=False)
    assert outcome.data.kind == "paper" and outcome.data.task == "toy-stock"
    assert "fill_per_hour (units/h) ↑" in (outcome.out_dir / "tables" / "task_utility.md").read_text(encoding="utf-8")
    board = make_leaderboards([root], tmp_path / "board", OPTIONS)
    assert board.boards[0].layout.task == "toy-stock"
    assert "| fill_per_hour (units/h) ↑ |" in board.files["leaderboard.md"].read_text(encoding="utf-8")


def test_a_grid_root_whose_units_ran_different_tasks_is_refused(toy_task, tmp_path):
    toy = write_toy_run(tmp_path / "a", toy_task, ("steady",))
    solar_like = write_toy_run(tmp_path / "b", toy_task, ("steady",))
    record = RunMetadata.read(solar_like / "run_metadata.json")
    record.model_copy(update={"task": "solar"}).write(solar_like / "run_metadata.json")
    root = _grid_root(tmp_path / "root", {"main-s7": toy, "main-s8": solar_like})
    with pytest.raises(
        ReportDataError, match=r"records task 'solar' but .* records task 'toy-stock'; a report covers one"
    ):
        build_report(root, formats=("md",), options=REPORT_OPTIONS, figures=False)
