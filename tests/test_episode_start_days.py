"""``start_days``: the configuration field behind the within-month splits (docs/dataset.md#splits).

The field parses days and ranges, restricts every back-end's episode starts (numpy env, vector
env, JAX twin, the supply market) to those days, enters the run's protocol only when set, and
the suites ``paper-early`` and ``paper-late`` evaluate on it exactly as ``evaluate`` does with
the same configuration.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig, ConfigError, load_config, parse_start_days, select_starts
from solarchain_eval.data.table import load_table
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.envs.vector import SolarChainVectorEnv
from solarchain_eval.evaluation.fingerprint import task_config_sha256
from solarchain_eval.report.leaderboard import make_leaderboards
from solarchain_eval.report.leaderboard.inputs import LeaderboardError
from solarchain_eval.tasks.registry import get_task
from solarchain_eval.tasks.suites import SuiteError, get_suite

runner = CliRunner()
LATE = list(range(22, 31))
EARLY = list(range(1, 22))


@pytest.mark.parametrize(
    ("value", "days"),
    [("1-21", EARLY), ("22-30", LATE), ("1-3, 8", [1, 2, 3, 8]), ([8, 1, 3], [1, 3, 8]), ("5", [5]), (None, None)],
)
def test_days_and_ranges_parse_to_sorted_days(value, days):
    assert parse_start_days(value) == days
    assert BenchmarkConfig(start_days=value).start_days == days


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("0-3", "day 0 is outside"),
        ("5-2", "the range '5-2' ends before it starts"),
        ("a", "'a' is neither a day nor a range"),
        ([1, 1], r"day\(s\) 1 given twice"),
        ("1-3,2", r"day\(s\) 2 given twice"),
        ([], "give at least one day"),
        ([1.5], "1.5 is not a day number"),
        (True, "give a list of day numbers"),
    ],
)
def test_bad_days_are_refused_naming_the_part(value, message):
    with pytest.raises(ValueError, match=message):
        parse_start_days(value)


def test_a_config_file_with_bad_days_is_one_line_naming_the_key(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("start_days: 30-1\n")
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert str(error.value).count("\n") == 0 and "start_days" in str(error.value) and "30-1" in str(error.value)


def test_select_starts_keeps_the_days_and_names_a_missing_one():
    midnights = np.arange(0, 697, 24)  # the paper's 30 days
    assert (select_starts(midnights, None, 24) is midnights) and len(midnights) == 30
    assert select_starts(midnights, LATE, 24).tolist() == [24 * (d - 1) for d in LATE]
    with pytest.raises(ConfigError, match=r"day\(s\) 31 of april have no episode start \(its start days are 1-30"):
        select_starts(midnights, [30, 31], 24, "april")
    mondays = np.array([0, 7, 14])  # a market of one step a day, whose episodes start on Mondays
    assert select_starts(mondays, [8, 15], 1).tolist() == [7, 14]
    with pytest.raises(ConfigError, match=r"day\(s\) 2 .* start days are 1, 8, 15"):
        select_starts(mondays, [2], 1)


@pytest.fixture(scope="module")
def table(published_dir):
    return load_table(published_dir)


def test_the_env_draws_only_the_configured_days(table):
    late = SolarChainEnv(config=BenchmarkConfig(start_days="22-30"), table=table)
    every = SolarChainEnv(table=table)
    drawn = {late.reset(seed=s)[1]["episode_start_hour"] for s in range(300)}
    assert drawn == {24 * (d - 1) for d in LATE}
    assert len({every.reset(seed=s)[1]["episode_start_hour"] for s in range(300)}) == 30
    with pytest.raises(ConfigError, match=r"day\(s\) 31"):
        SolarChainEnv(config=BenchmarkConfig(start_days=[31]), table=table)


def test_the_vector_env_draws_as_single_envs_do_on_restricted_days(table):
    cfg = BenchmarkConfig(start_days="1-21")
    vec = SolarChainVectorEnv(4, config=cfg, table=table)
    singles = [SolarChainEnv(config=cfg, table=table) for _ in range(4)]
    starts = []
    for seed in range(0, 200, 4):
        _, info = vec.reset(seed=seed)
        expected = [env.reset(seed=seed + i)[1]["episode_start_hour"] for i, env in enumerate(singles)]
        assert info["episode_start_hour"].tolist() == expected
        starts.extend(expected)
    assert {h // 24 + 1 for h in starts} == set(EARLY)


def test_the_jax_twin_has_the_numpy_envs_starts(table):
    pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
    import jax

    from solarchain_eval.envs.jax_env import SolarChainJaxEnv, make_env_params

    cfg = BenchmarkConfig(start_days="22-30")
    params = make_env_params(config=cfg, table=table)
    assert np.asarray(params.start_hours).tolist() == SolarChainEnv(config=cfg, table=table)._starts.tolist()
    env = SolarChainJaxEnv(params)
    keys = jax.random.split(jax.random.PRNGKey(0), 200)
    _, states = jax.vmap(env.reset_env, in_axes=(0, None))(keys, params)
    assert {int(h) // 24 + 1 for h in np.asarray(states.start)} == set(LATE)


def test_the_supply_market_keeps_its_monday_starts_on_the_days():
    from solarchain_eval.supply.env import SupplyChainEnv

    every = SupplyChainEnv()
    mondays = every.inputs.starts
    days = [int(mondays[1]) + 1, int(mondays[3]) + 1]
    restricted = SupplyChainEnv(config=BenchmarkConfig(episode_steps=every.episode_steps, start_days=days))
    assert restricted.inputs.starts.tolist() == [mondays[1], mondays[3]]
    assert {restricted.reset(seed=s)[1]["episode_start_day"] for s in range(50)} == {mondays[1], mondays[3]}
    with pytest.raises(ConfigError, match=rf"day\(s\) {int(mondays[1]) + 2} "):
        SupplyChainEnv(config=BenchmarkConfig(episode_steps=every.episode_steps, start_days=[int(mondays[1]) + 2]))


def test_the_protocol_names_the_days_only_when_set():
    every, late = BenchmarkConfig(), BenchmarkConfig(start_days="22-30")
    assert "start_days" not in get_task().protocol_config(every)
    assert get_task().identity(every) == {"env": "SolarChainEval-v0"}
    assert get_task().identity(late)["start_days"] == LATE
    assert task_config_sha256(late) != task_config_sha256(every)
    assert task_config_sha256(BenchmarkConfig(start_days=LATE)) == task_config_sha256(late)  # text or list


@pytest.fixture(scope="module")
def within_month(published_dir, tmp_path_factory):
    root = tmp_path_factory.mktemp("within")
    out = {}
    for name in ("paper-early", "paper-late"):
        out[name] = solarchain_eval.evaluate("static", suite=name, seeds=(20260511,), episodes=12, out=root / name)
    return root, out


def test_the_within_month_suites_start_on_their_days_only(within_month):
    root, results = within_month
    for name, days in (("paper-early", EARLY), ("paper-late", LATE)):
        suite = get_suite(name)
        ((entry),) = suite.entries
        assert suite.splits == (name,) and entry.config_overrides == {"start_days": days}
        metrics = pd.read_csv(root / name / entry.name / "metrics.csv")
        assert set(metrics["start_hour"] // 24 + 1) <= set(days) and len(metrics) == 36
        protocol = json.loads((root / name / entry.name / "run_metadata.json").read_text())["protocol"]
        assert protocol["start_days"] == days
        assert results[name].protocol["splits"] == [name]
    early, late = (results[n].runs["paper-2026-04"].protocol_id for n in ("paper-early", "paper-late"))
    assert len({early, late, "89e17532f325"}) == 3


def test_a_within_month_suite_equals_evaluate_with_the_days(within_month, published_dir, tmp_path):
    _, results = within_month
    alone = solarchain_eval.evaluate(
        ["static", "random", "myopic"],
        data=published_dir,
        config=BenchmarkConfig(start_days="22-30"),
        seeds=(20260511,),
        episodes=12,
        out=tmp_path / "alone",
    )
    suite_run = results["paper-late"].runs["paper-2026-04"]
    assert alone.protocol_id == suite_run.protocol_id
    scores = results["paper-late"].scores.set_index(["policy", "episode"])["score"]
    for row in alone.metrics.itertuples():
        assert scores[(row.policy, row.episode)] == row.cumulative_reward


def test_a_config_with_other_days_is_refused_by_a_within_month_suite(published_dir, tmp_path):
    entry = get_suite("paper-late").entries[0]
    with pytest.raises(SuiteError, match="fixes start_days"):
        entry.configure(BenchmarkConfig(start_days="1-21"))
    assert entry.configure(BenchmarkConfig(start_days="22-30")).start_days == LATE  # the same days: fine
    (tmp_path / "early.yaml").write_text('start_days: "1-21"\n')
    out = tmp_path / "never"
    done = runner.invoke(
        app, ["evaluate", "--suite", "paper-late", "--config", str(tmp_path / "early.yaml"), "--out", str(out)]
    )
    assert done.exit_code == 2 and "fixes start_days" in done.output and len(done.output.strip().splitlines()) == 1
    assert not out.exists()


def test_within_month_roots_verify_and_never_share_a_board(within_month, tmp_path):
    root, _ = within_month
    done = runner.invoke(app, ["verify", str(root / "paper-late"), "--episodes", "1"])
    assert done.exit_code == 0, done.output
    with pytest.raises(LeaderboardError, match="suites of different splits"):
        make_leaderboards([root / "paper-early", root / "paper-late"], tmp_path / "mixed")
