"""The leaderboard: ranking against a direct computation, the protocol rule (refusal, --split),
duplicate names, older runs, tarballs, the paper's reference rows, the Pareto front and the
sortable page in a real browser."""

from __future__ import annotations

import json
import re
import shutil
import tarfile
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from chromium import find_chromium, open_page
from solarchain_eval.cli import app
from solarchain_eval.data.default import default_dataset_dir
from solarchain_eval.evaluation.fingerprint import protocol_id
from solarchain_eval.report.against_paper.paper_reference import paper_value
from solarchain_eval.report.leaderboard import make_leaderboards
from solarchain_eval.report.leaderboard.inputs import LeaderboardError, open_inputs
from solarchain_eval.report.leaderboard.pareto import pareto_front
from solarchain_eval.report.leaderboard.ranking import (
    REFERENCE,
    REFERENCE_SOURCE,
    build_leaderboard,
    is_paper_protocol,
    paired_improvement,
    paper_protocol,
    rank_setting,
    reference_rows,
)
from solarchain_eval.report.leaderboard.render import render_html, render_markdown
from solarchain_eval.report.loading import ReportDataError
from solarchain_eval.report.naming import policy_label
from solarchain_eval.report.options import DEFAULT_SEED, LeaderboardOptions
from solarchain_eval.report.statistics import bootstrap_mean

SEED, EPISODES = 20260511, 3
OPTIONS = LeaderboardOptions(n_resamples=200)
BASELINES = ("static", "random", "myopic")


def my_agent(observation):
    return [0.3, 0.7, 0.05]


def bold_agent(observation):
    return [0.6, 0.4, 0.0]


def _cli(*args: str):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> SimpleNamespace:
    """A run with a user agent, and a ``paper --preset smoke`` root of the same protocol (1 seed × 3 episodes)."""
    base = tmp_path_factory.mktemp("leaderboard")
    solarchain_eval.evaluate([my_agent, "static", "myopic"], seeds=[SEED], episodes=EPISODES, out=base / "run_a")
    root = base / "smoke"
    made = _cli("paper", "--preset", "smoke", "--episodes", EPISODES, "--policies", "static,random,myopic,dqn",
                "--out", root, "--no-report")  # fmt: skip
    assert made.exit_code == 0, made.output
    return SimpleNamespace(base=base, run_a=base / "run_a", root=root)


@pytest.fixture(scope="module")
def other_dataset_run(runs) -> Path:
    """The same protocol on a dataset that differs from the default in one value of one CSV."""
    data = runs.base / "edited-data"
    shutil.copytree(default_dataset_dir(), data)
    path = data / "market_liquidity.csv"
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    assert lines[1].rstrip().endswith(",8.6111")
    lines[1] = lines[1].replace(",8.6111", ",8.6112")
    path.write_text("".join(lines), encoding="utf-8")
    out = runs.base / "run_other_data"
    solarchain_eval.evaluate(["static"], data=data, seeds=[SEED], episodes=EPISODES, out=out)
    return out


def _board(*paths, options=OPTIONS, references=None):
    with open_inputs(list(paths)) as sections:
        return build_leaderboard(sections, options, references)


def _section(board, setting):
    return next(s for s in board.sections if s.setting == setting)


def test_ranking_and_intervals_match_a_direct_computation(runs):
    board = _board(runs.run_a, runs.root)
    assert [s.setting for s in board.sections] == ["main", "no_physics", "llm", "llm_no_physics"]
    main = _section(board, "main")
    own = pd.read_csv(runs.run_a / "metrics.csv")
    grid = pd.read_csv(runs.root / "combined" / "main" / "metrics.csv")
    rows = pd.concat([own, grid[~grid["policy"].isin(own["policy"])]], ignore_index=True)
    means = rows.groupby("policy")["cumulative_reward"].mean().sort_values(ascending=False)
    ranked = main.ranked.set_index("policy")
    assert list(main.ranked["policy"]) == list(means.index)  # best mean first
    assert list(main.ranked["rank"]) == [1, 2, 3, 4, 5]
    best = max(BASELINES, key=lambda p: means[p])
    assert main.best_baseline == best
    for policy, group in rows.groupby("policy"):
        values = np.sort(group["cumulative_reward"].to_numpy())
        row = ranked.loc[policy]
        assert row["cumulative_reward_mean"] == pytest.approx(values.mean(), abs=1e-12)
        assert row["cumulative_reward_std"] == pytest.approx(values.std(ddof=1), abs=1e-12)
        # IQM of three values: mass 0.75..2.25 -> weights 1/4, 1, 1/4 over 1.5.
        assert row["cumulative_reward_iqm"] == pytest.approx((0.25 * values[0] + values[1] + 0.25 * values[2]) / 1.5)
        interval = bootstrap_mean(group["cumulative_reward"], group["start_hour"], n_resamples=200, seed=DEFAULT_SEED)
        assert (row["cumulative_reward_low"], row["cumulative_reward_high"]) == (interval.low, interval.high)
        assert values[0] - 1e-9 <= row["cumulative_reward_low"] < row["cumulative_reward_high"] <= values[-1] + 1e-9
        pairs = group.merge(rows[rows["policy"] == best], on=["run_seed", "episode"], suffixes=("", "_b"))
        x, y = pairs["cumulative_reward"].to_numpy(), pairs["cumulative_reward_b"].to_numpy()
        assert row["p_improvement"] == pytest.approx(np.mean((x > y) + 0.5 * (x == y)))
        assert 0.0 <= row["p_improvement_low"] <= row["p_improvement"] <= row["p_improvement_high"] <= 1.0
        for metric in ("physics_violation_rate", "artificial_liquidity_MWh", "action_jitter"):
            assert row[f"{metric}_mean"] == pytest.approx(group[metric].mean(), abs=1e-12)
    assert ranked.loc["my_agent", "source"] == str(runs.run_a) and ranked.loc["random", "source"] == str(runs.root)
    assert set(ranked["access"]) == {"in-process"}
    # The root's static and myopic repeat the run's row for row: kept once, with a note.
    assert any("static in main" in note and "kept once" in note for note in board.notes)
    llm = _section(board, "llm")
    assert list(llm.ranked["access"]) == ["privileged"] and llm.best_baseline is None
    assert np.isnan(llm.ranked["p_improvement"].iloc[0])
    # The root's sections merge their units' protocols: main's id is the run's own protocol id.
    assert main.protocol_id == json.loads((runs.run_a / "run_metadata.json").read_text())["protocol_id"]


def test_cli_writes_the_board_files(runs, tmp_path):
    out = tmp_path / "board"
    result = _cli("leaderboard", runs.run_a, runs.root, "--out", out, "--resamples", 200)
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == [
        "leaderboard.csv", "leaderboard.html", "leaderboard.md", "pareto.png", "pareto.svg",
    ]  # fmt: skip
    frame = pd.read_csv(out / "leaderboard.csv")
    main = frame[frame["setting"] == "main"]
    assert list(main["cumulative_reward_mean"]) == sorted(main["cumulative_reward_mean"], reverse=True)
    assert frame["board_protocol_id"].nunique() == 1 and frame["protocol_id"].nunique() == 4
    page = (out / "leaderboard.html").read_text(encoding="utf-8")
    assert not re.search(r'(href|src)="(https?:)?//', page)
    assert re.findall(r'\ssrc="([^"]*)"', page)[0].startswith("data:image/png;base64,")
    assert page.count('<table class="board"') == 4
    markdown = (out / "leaderboard.md").read_text(encoding="utf-8")
    first = policy_label(main["policy"].iloc[0])
    assert "## Main (protocol id" in markdown and f"| 1 | {first} | in-process |" in markdown
    csv_only = _cli("leaderboard", runs.run_a, "--out", tmp_path / "csv", "--formats", "csv", "--resamples", 200)
    assert csv_only.exit_code == 0 and sorted(p.name for p in (tmp_path / "csv").iterdir()) == ["leaderboard.csv"]
    bad = _cli("leaderboard", runs.run_a, "--out", tmp_path / "bad", "--formats", "pdf")
    assert bad.exit_code == 2 and "unknown leaderboard format(s) pdf" in bad.output
    assert not (tmp_path / "bad").exists()


def test_another_dataset_is_refused_naming_the_field_or_split(runs, other_dataset_run, tmp_path):
    out = tmp_path / "board"
    refused = _cli("leaderboard", runs.run_a, other_dataset_run, "--out", out)
    assert refused.exit_code == 2
    message = " ".join(refused.output.split())
    assert "dataset_sha256[market_liquidity.csv]" in message
    assert f"{runs.run_a} [main]" in message and f"{other_dataset_run} [main]" in message and "--split" in message
    assert not out.exists()  # nothing written

    split = _cli("leaderboard", runs.run_a, other_dataset_run, "--out", out, "--split", "--resamples", 200)
    assert split.exit_code == 0, split.output
    with open_inputs([runs.run_a, other_dataset_run]) as sections:
        ids = {s.source: s.board_id for s in sections}
    assert sorted(p.name for p in out.iterdir()) == sorted(ids.values())
    for source, board_id in ids.items():
        frame = pd.read_csv(out / board_id / "leaderboard.csv")
        assert set(frame["source"]) == {source} and set(frame["board_protocol_id"]) == {board_id}
        assert (out / board_id / "leaderboard.html").is_file()


def test_one_name_with_different_results_is_refused(runs, tmp_path):
    other = tmp_path / "run_dup"
    # (a built-in's name is the benchmark's own: tests/test_agent_attacks.py)
    solarchain_eval.evaluate(bold_agent, name="my_agent", seeds=[SEED], episodes=EPISODES, out=other)
    refused = _cli("leaderboard", runs.run_a, other, "--out", tmp_path / "board")
    assert refused.exit_code == 2
    message = " ".join(refused.output.split())
    assert "policy 'my_agent' of setting 'main'" in message and str(runs.run_a) in message and str(other) in message
    assert not (tmp_path / "board").exists()
    twice = _board(runs.run_a, runs.run_a)  # the same run twice: identical rows, ranked once
    assert list(_section(twice, "main").ranked["policy"]) == list(_section(_board(runs.run_a), "main").ranked["policy"])


def test_a_run_without_a_recorded_protocol(runs, tmp_path):
    legacy = tmp_path / "legacy"
    shutil.copytree(runs.run_a, legacy)
    metadata = json.loads((legacy / "run_metadata.json").read_text())
    for key in ("protocol", "protocol_id", "policy_access"):
        metadata.pop(key)
    metadata["episode_seed_protocol"] = "paper_episode_seeds"  # what older versions recorded
    (legacy / "run_metadata.json").write_text(json.dumps(metadata))
    with open_inputs([runs.run_a]) as current, open_inputs([legacy]) as old:
        assert old[0].board_id == current[0].board_id and old[0].protocol_id == current[0].protocol_id
        assert set(old[0].access.values()) == {"unknown"}
    metadata.pop("config")  # every version recorded it: a file without it is malformed
    (legacy / "run_metadata.json").write_text(json.dumps(metadata))
    with (
        pytest.raises(ReportDataError, match=r"run_metadata\.json: field config: Field required"),
        open_inputs([legacy]),
    ):
        pass


def test_units_of_one_setting_under_different_protocols_are_refused(runs, tmp_path):
    root = tmp_path / "root"
    shutil.copytree(runs.root, root)
    path = root / "units" / "eval" / "static-no_physics-20260511" / "run_metadata.json"
    metadata = json.loads(path.read_text())
    metadata["protocol"]["episodes"] = EPISODES + 1  # what another budget would record
    metadata["protocol_id"] = protocol_id(metadata["protocol"])
    path.write_text(json.dumps(metadata))
    with pytest.raises(LeaderboardError) as refused, open_inputs([root]):
        pass
    message = str(refused.value)
    assert "static-no_physics-20260511 were evaluated under different protocols" in message
    assert f"protocol field 'episodes': {EPISODES} vs {EPISODES + 1}" in message


def test_a_tarball_is_read_as_its_run(runs, tmp_path):
    tarball = tmp_path / "submission.tar.gz"
    with tarfile.open(tarball, "w:gz") as archive:
        archive.add(runs.run_a, arcname="my-run")
    from_tar, from_dir = _board(tarball), _board(runs.run_a)
    frame = from_tar.frame()
    assert set(frame["source"]) == {str(tarball)}
    pd.testing.assert_frame_equal(frame.drop(columns="source"), from_dir.frame().drop(columns="source"))


def test_paper_protocol_and_reference_rows(runs):
    main = reference_rows("main").set_index("policy")
    stored = paper_value("main-performance:static:cumulative_reward:mean")["value"]
    assert list(main.index) == ["static", "random", "myopic", "ppo", "sac", "dqn"]  # the paper's rows, no pooled row
    assert main.loc["static", "cumulative_reward_mean"] == stored == -23.38
    assert (
        main.loc["sac", "physics_violation_rate_mean"]
        == paper_value("main-performance:sac:physics_violation_rate:mean")["value"]
    )
    assert set(reference_rows("no_physics")["policy"]) == {"ppo", "sac", "dqn"}  # not the ablation's differences
    assert is_paper_protocol(paper_protocol("no_physics"))
    for field, value in (("episodes", 3), ("run_seeds", [SEED]), ("episode_seed_rule", "independent")):
        assert not is_paper_protocol({**paper_protocol("main"), field: value})
    assert not is_paper_protocol(
        {**paper_protocol("main"), "config_sha256": paper_protocol("no_physics")["config_sha256"]}
    )
    published = pd.DataFrame({"policy": ["ppo", "static"], "cumulative_reward_mean": [1.25, -0.5],
                              "cumulative_reward_std": [0.125, 0.25], "physics_violation_rate_mean": [0.1, 0.2]})  # fmt: skip
    with open_inputs([runs.run_a]) as sections:
        ours = rank_setting("main", sections, OPTIONS, "b0", lambda setting: published)
        assert ours.reference is None  # not the paper's protocol: no reference rows
        as_paper = [replace(sections[0], protocol={**paper_protocol("main"), "action_modes": {}})]
        section = rank_setting("main", as_paper, OPTIONS, "b0", lambda setting: published)
    assert section.paper_protocol and section.reference is not None
    rows = section.rows()
    reference = rows[rows["row_kind"] == REFERENCE]
    assert list(reference["policy"]) == ["ppo", "static"] and reference["rank"].isna().all()
    assert set(reference["source"]) == {REFERENCE_SOURCE}
    board = replace(_board(runs.run_a), sections=[section])
    markdown = render_markdown(board)
    assert "| paper | PPO | – | paper (published) | – | 1.25 ± 0.12 | – | – | 0.1000 |" in markdown
    page = render_html(board, None)
    assert page.count('<tr class="reference"') == 2 and "1.25 ± 0.12" in page


def test_paired_improvement_needs_the_same_episodes():
    x = pd.DataFrame({"run_seed": [1, 1, 1], "episode": [0, 1, 2], "episode_seed": [1, 2, 3],
                      "start_hour": [0, 24, 48], "cumulative_reward": [1.0, 2.0, 3.0]})  # fmt: skip
    y = x.assign(cumulative_reward=[0.0, 2.0, 4.0])
    assert paired_improvement(x, y, n_resamples=200).estimate == pytest.approx((1 + 0.5 + 0) / 3)
    with pytest.raises(LeaderboardError, match="episode seeds"):
        paired_improvement(x, y.assign(episode_seed=[1, 2, 9]), n_resamples=200)


def test_pareto_front():
    liquidity = [0.1, 0.2, 0.3, 0.15, 0.3, float("nan")]
    reward = [1.0, 2.0, 3.0, 0.5, 2.5, 9.0]
    # (0.15, 0.5) is dominated by (0.1, 1.0); (0.3, 2.5) by (0.3, 3.0); NaN is never on it.
    assert list(pareto_front(liquidity, reward)) == [True, True, True, False, False, False]


def test_the_page_sorts_by_a_clicked_header_in_chromium(runs, tmp_path):
    if find_chromium() is None:
        pytest.skip("Chromium is not installed (Debian: apt-get install -y chromium)")
    pytest.importorskip("websocket", reason="the websocket-client package (test extra) drives Chromium")
    out = tmp_path / "board"
    assert _cli("leaderboard", runs.run_a, runs.root, "--out", out, "--resamples", 200).exit_code == 0
    main = pd.read_csv(out / "leaderboard.csv").query("setting == 'main'")
    order = "JSON.stringify(Array.from(document.querySelectorAll('#board-main tbody tr')).map(r => r.dataset.policy))"
    violation = "#board-main thead th:nth-child(9)"
    reward = "#board-main thead th:nth-child(6)"
    page, _ = open_page(
        out / "leaderboard.html",
        actions=[
            ("eval", order),
            ("click", violation),
            ("eval", order),
            ("click", violation),
            ("eval", order),
            ("click", reward),
            ("eval", order),
        ],  # fmt: skip
    )
    assert page.console_errors == []
    ranked, _, safest, _, least_safe, _, best = (json.loads(r) if r else r for r in page.results)
    by_violation = main.sort_values("physics_violation_rate_mean")["policy"].tolist()
    assert ranked == main["policy"].tolist()
    assert safest == by_violation and least_safe == by_violation[::-1] and safest != ranked
    assert best == main.sort_values("cumulative_reward_mean", ascending=False)["policy"].tolist()


def test_a_run_of_the_paper_protocol_shows_the_reference_rows(published_dir, tmp_path):
    """The paper's protocol needs its 3 seeds × 30 episodes on the published data (static alone: seconds)."""
    run = tmp_path / "paper-static"
    evaluation = solarchain_eval.evaluate(["static"], data=published_dir, out=run)
    assert is_paper_protocol(evaluation.protocol)
    published = pd.DataFrame({"policy": ["static"], "cumulative_reward_mean": [-1.5], "cumulative_reward_std": [0.25]})
    outcome = make_leaderboards([run], tmp_path / "board", OPTIONS, references=lambda setting: published)
    frame = pd.read_csv(tmp_path / "board" / "leaderboard.csv")
    assert list(frame["row_kind"]) == ["ranked", REFERENCE] and list(frame["source"]) == [str(run), REFERENCE_SOURCE]
    assert frame["cumulative_reward_mean"].iloc[1] == -1.5 and outcome.boards[0].sections[0].paper_protocol
    assert "-1.50 ± 0.25" in (tmp_path / "board" / "leaderboard.html").read_text(encoding="utf-8")


def test_verify_rebuilds_a_grids_learned_policy_from_its_own_train_unit(runs):
    # The keeper named the root: a unit's recorded model inside it is the grid's own (docs/security.md).
    result = _cli("verify", runs.root, "--episodes", 1)
    assert result.exit_code == 0, result.output
    assert "  dqn: verified (1 episode)" in result.output.splitlines()
