"""The contrast tables of a task without a paper reference (report/task_contrast.py): each declared
setting contrast's difference treated - base per policy and metric, checked against a numpy
computation of the same cluster bootstrap on the same rows; paired where the settings ran the same
episodes, resampled jointly where they did not."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from solarchain_eval.report.loading import ReportData
from solarchain_eval.report.options import ReportOptions
from solarchain_eval.report.table_model import ReportTable, Skipped, to_latex, to_markdown
from solarchain_eval.report.task_contrast import (
    contrast_frame,
    same_episodes,
    task_contrast_figure,
    task_contrast_tables,
)
from solarchain_eval.tasks.registry import UnknownTaskError, get_task, register_task, unregister_task
from toy_task import ToyTask

OPTIONS = ReportOptions(n_resamples=400, seed=11)
METRICS = ("total_reward", "shortfall_units", "stock_swing")
RUN_SEEDS, EPISODES = (1, 2), 6


@pytest.fixture()
def toy():
    """The toy task (no paper reference) registered as ``toy-stock`` for the test."""
    try:
        before = get_task("toy-stock")
    except UnknownTaskError:
        before = None
    register_task(ToyTask())
    yield
    unregister_task("toy-stock")
    if before is not None:
        register_task(before)


def _rows(setting: str, policy: str, episodes: int, shift: dict[str, float], rng) -> list[dict]:
    """Rollouts whose metrics carry a strong start-day effect (shared by every setting) plus ``shift``."""
    day_effect = {day: 10.0 * day for day in range(5)}
    rows = []
    for run_seed in RUN_SEEDS:
        for episode in range(episodes):
            seed = run_seed + episode  # the paper protocol: consecutive run seeds share episode seeds
            day = seed % 5
            row = {"policy": policy, "setting": setting, "run_seed": run_seed, "episode": episode}
            row |= {"episode_seed": seed, "start_hour": 24 * day}
            for i, metric in enumerate(METRICS):
                row[metric] = day_effect[day] * (i + 1) + shift.get(metric, 0.0) + rng.normal(0.0, 0.5)
            rows.append(row)
    return rows


def _data() -> ReportData:
    rng = np.random.default_rng(5)
    rows = []
    for policy in ("steady", "ppo"):
        rows += _rows("main", policy, EPISODES, {}, rng)
        # dropping the penalty: ppo promises more stock it does not have
        rows += _rows("no_physics", policy, EPISODES, {"shortfall_units": 3.0 if policy == "ppo" else 0.0}, rng)
    # governed ppo ran fewer episodes: not the same episodes as main, so not paired
    rows += _rows("llm", "ppo", EPISODES - 2, {"shortfall_units": -2.0, "total_reward": -1.0}, rng)
    empty = pd.DataFrame()
    return ReportData(Path("toy-root"), "paper", pd.DataFrame(rows), empty, empty, empty, task="toy-stock")


def _numpy_interval(labels: np.ndarray, statistic) -> tuple[float, float]:
    """The percentile interval of ``statistic`` over cluster resamples, drawn as scipy's bootstrap draws them
    (one batch of ``rng.integers`` indices into the sorted cluster labels, linear quantiles)."""
    days, codes = np.unique(labels, return_inverse=True)
    draws = np.random.default_rng(OPTIONS.seed).integers(0, days.size, (OPTIONS.n_resamples, days.size))
    counts = np.stack([np.bincount(draw, minlength=days.size) for draw in draws]).astype(float)
    replicates = statistic(counts[:, codes])
    alpha = (1 - OPTIONS.confidence) / 2
    low, high = np.quantile(replicates, [alpha, 1 - alpha])
    return float(low), float(high)


def _row(frame: pd.DataFrame, comparison: str, policy: str, metric: str) -> pd.Series:
    found = frame[(frame["comparison"] == comparison) & (frame["policy"] == policy) & (frame["metric"] == metric)]
    assert len(found) == 1
    return found.iloc[0]


def test_a_paired_difference_and_its_interval_match_numpy(toy):
    data = _data()
    frame = contrast_frame(data, OPTIONS)
    metrics = data.metrics
    base = metrics[(metrics.setting == "main") & (metrics.policy == "ppo")].set_index(["run_seed", "episode"])
    treated = metrics[(metrics.setting == "no_physics") & (metrics.policy == "ppo")].set_index(["run_seed", "episode"])
    assert same_episodes(base.reset_index(), treated.reset_index())
    for metric in METRICS:
        deltas = (treated[metric] - base[metric]).sort_index()
        days = base.loc[deltas.index, "start_hour"].to_numpy()
        d = deltas.to_numpy()
        low, high = _numpy_interval(days, lambda w, d=d: (w @ d) / w.sum(axis=1))
        row = _row(frame, "no_physics − main", "ppo", metric)
        assert bool(row["paired"]) and row["n"] == len(d)
        assert row["difference"] == pytest.approx(d.mean(), abs=1e-12)
        assert row["base_mean"] == pytest.approx(base[metric].mean(), abs=1e-12)
        assert row["treated_mean"] == pytest.approx(treated[metric].mean(), abs=1e-12)
        assert (row["low"], row["high"]) == pytest.approx((low, high), abs=1e-12)
        per_seed = deltas.groupby(level="run_seed").mean()
        assert row["run_seeds"] == list(RUN_SEEDS)
        assert row["seed_differences"] == pytest.approx(per_seed.to_list(), abs=1e-12)
        assert row["excludes_zero"] == (low > 0 or high < 0)
    # the day effect cancels out of the pairs: the shift of 3 units is found, tightly
    shortfall = _row(frame, "no_physics − main", "ppo", "shortfall_units")
    assert 2.0 < shortfall["low"] < 3.0 < shortfall["high"] < 4.0 and shortfall["excludes_zero"]


def test_an_unpaired_difference_resamples_both_settings_days_jointly(toy):
    data = _data()
    frame = contrast_frame(data, OPTIONS)
    metrics = data.metrics
    base = metrics[(metrics.setting == "main") & (metrics.policy == "ppo")]
    treated = metrics[(metrics.setting == "llm") & (metrics.policy == "ppo")]
    assert not same_episodes(base, treated)
    for metric in METRICS:
        x, y = treated[metric].to_numpy(), base[metric].to_numpy()
        labels = np.concatenate([treated["start_hour"].to_numpy(), base["start_hour"].to_numpy()])

        def difference(w, x=x, y=y):
            wx, wy = w[:, : x.size], w[:, x.size :]
            return (wx @ x) / wx.sum(axis=1) - (wy @ y) / wy.sum(axis=1)

        low, high = _numpy_interval(labels, difference)
        row = _row(frame, "llm − main", "ppo", metric)
        assert not bool(row["paired"]) and row["n"] == x.size + y.size
        assert row["difference"] == pytest.approx(x.mean() - y.mean(), abs=1e-12)
        assert (row["low"], row["high"]) == pytest.approx((low, high), abs=1e-12)
        by_seed = treated.groupby("run_seed")[metric].mean() - base.groupby("run_seed")[metric].mean()
        assert row["seed_differences"] == pytest.approx(by_seed.to_list(), abs=1e-12)
    # the baseline has no governed rollouts: only policies in both settings are compared
    assert set(frame.loc[frame["comparison"] == "llm − main", "policy"]) == {"ppo"}


def test_tables_mark_intervals_that_exclude_zero_and_skip_what_the_run_lacks(toy, tmp_path):
    data = _data()
    frame = contrast_frame(data, OPTIONS)
    tables = {t.key: t for t in task_contrast_tables(data, OPTIONS, frame)}
    assert list(tables) == ["task_contrast_ablation", "task_contrast_governance"]
    ablation, governance = tables["task_contrast_ablation"], tables["task_contrast_governance"]
    assert isinstance(ablation, ReportTable) and isinstance(governance, ReportTable)
    text = to_markdown(ablation)
    shortfall = _row(frame, "no_physics − main", "ppo", "shortfall_units")
    cell = f"{shortfall['difference']:.3f} [{shortfall['low']:.3f}, {shortfall['high']:.3f}] *"
    assert "| no_physics − main | ppo | safety | shortfall_units (units) ↓ |" in text and cell in text
    assert r"no\_physics $-$ main & ppo & safety & shortfall\_units (units) $\downarrow$" in to_latex(ablation)
    steady = _row(frame, "no_physics − main", "steady", "stock_swing")
    assert not steady["excludes_zero"]  # no shift: the interval holds 0 and carries no mark
    assert f"[{steady['low']:.3f}, {steady['high']:.3f}] |" in text
    assert "llm − main, ppo: the two settings ran different episodes" in " ".join(governance.notes)
    # rows by policy, metrics grouped by dimension in the template's order
    dims = list(ablation.data.loc[ablation.data["policy"] == "ppo", "dimension"])
    assert dims == ["utility", "safety", "stability"]  # one ablation contrast held: no_physics - main
    figure = task_contrast_figure(data, OPTIONS, tmp_path, frame)
    assert not isinstance(figure, Skipped) and figure.png.stat().st_size > 0 and figure.svg.exists()
    only_main = ReportData(Path("r"), "run", data.rollouts("main"), *(pd.DataFrame(),) * 3, task="toy-stock")
    skipped = task_contrast_tables(only_main, OPTIONS)
    assert all(isinstance(t, Skipped) for t in skipped)
    assert "the run has main" in skipped[0].reason
