"""User agents (agent specs) in ``paper``, ``governance`` and ``sweep``: eval-only units in every
setting, the same rows as ``evaluate``, resume, the report's labels, and errors before any work."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.experiments.grid import GridSpec, plan_units

AGENT_FILE = '''
import numpy as np


class Steady:
    """The same action every hour."""

    action_mode = "continuous"

    def __init__(self, level=0.5):
        self.level = float(level)

    def act(self, observation):
        return np.array([self.level, 0.0, 0.5], dtype=np.float32)


class Keyed(Steady):
    """Steady, with a credential it is built with (which no file of the grid may record)."""

    def __init__(self, level=0.5, api_token=None):
        super().__init__(level)
        self.api_token = api_token
'''
MODULE = "grid_agents_test_mod"
MODULE_FILE = """
import numpy as np


def hold(observation):
    return np.zeros(3, dtype=np.float32)


def Myopic(observation):  # its own name is a built-in policy's
    return np.zeros(3, dtype=np.float32)


def wrong(observation):  # an action of the wrong shape
    return np.zeros(5, dtype=np.float32)
"""
SEED = 7


def invoke(args: list[str]):
    return CliRunner().invoke(app, args)


@pytest.fixture(scope="module")
def agents_dir(tmp_path_factory):
    """A file agent (``steady.py:Steady``) and an importable module with functions."""
    folder = tmp_path_factory.mktemp("agents")
    (folder / "steady.py").write_text(AGENT_FILE, encoding="utf-8")
    (folder / f"{MODULE}.py").write_text(MODULE_FILE, encoding="utf-8")
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(folder))
        yield folder


def _paper(root: Path, data: Path, agents: Path, *extra: str) -> list[str]:
    return [
        "paper",
        "--preset",
        "smoke",
        "--out",
        str(root),
        "--data",
        str(data),
        "--settings",
        "main,llm",
        "--seeds",
        str(SEED),
        "--policies",
        f"static,mine={agents / 'steady.py'}:Steady,{MODULE}:hold",
        *extra,
    ]


@pytest.fixture(scope="module")
def paper_root(tmp_path_factory, tiny_dataset, agents_dir) -> Path:
    root = tmp_path_factory.mktemp("paper") / "root"
    result = invoke(_paper(root, tiny_dataset, agents_dir, "--agent-arg", "mine.level=0.2"))
    assert result.exit_code == 0, result.output
    return root


def _units(root: Path) -> list[str]:
    return sorted(str(p.parent.relative_to(root / "units")) for p in (root / "units").glob("*/*/DONE"))


def test_the_plan_gives_user_agents_eval_units_in_every_setting_and_no_train_units():
    agents = (("mine", "steady.py:Steady"),)
    spec = GridSpec(
        timesteps=10, episodes=1, seeds=(1,), settings=("main", "llm"), policies=("static", "ppo"), agents=agents
    )
    assert [(u.name, u.depends_on) for u in plan_units(spec)] == [
        ("train/ppo-main-1", ()),
        ("eval/static-main-1", ()),
        ("eval/ppo-main-1", ("train/ppo-main-1",)),
        ("eval/mine-main-1", ()),
        ("eval/ppo-llm-1", ("train/ppo-main-1",)),
        ("eval/mine-llm-1", ()),
    ]
    # a list per setting (a sweep's grid.policies) names the agent where it runs
    only_main = GridSpec(
        timesteps=10,
        episodes=1,
        seeds=(1,),
        settings=("main", "llm"),
        policies_by_setting=(("main", ("static", "mine")), ("llm", ("ppo",))),
        agents=agents,
    )
    only_main.validate()
    assert [u.name for u in plan_units(only_main) if u.kind == "eval"] == [
        "eval/static-main-1",
        "eval/mine-main-1",
        "eval/ppo-llm-1",
    ]
    # user agents alone are a grid too; a built-in's name is refused, in any case
    GridSpec(timesteps=10, episodes=1, seeds=(1,), settings=("main",), policies=(), agents=agents).validate()
    with pytest.raises(ValueError, match="'PPO' is reserved for the benchmark's own 'ppo'"):
        GridSpec(timesteps=10, episodes=1, seeds=(1,), agents=(("PPO", "steady.py:Steady"),)).validate()


def test_paper_runs_user_agents_as_eval_units_behind_the_layer_in_the_agentic_setting(paper_root, agents_dir):
    assert _units(paper_root) == [
        f"eval/hold-llm-{SEED}",
        f"eval/hold-main-{SEED}",
        f"eval/mine-llm-{SEED}",
        f"eval/mine-main-{SEED}",
        f"eval/static-main-{SEED}",
    ]
    assert not (paper_root / "units" / "train").exists()
    main = pd.read_csv(paper_root / "combined" / "main" / "metrics.csv")
    assert list(main["policy"].unique()) == ["static", "mine", "hold"] and len(main) == 3 * 2
    agentic = pd.read_csv(paper_root / "combined" / "llm" / "metrics.csv")
    assert list(agentic["policy"].unique()) == ["mine", "hold"]
    assert (agentic["planner"] == "rule").all() and (agentic["audit_rate"] > 0).all()
    # the unit records the spec, its options and the file's sha256 (resume compares them)
    spec = f"mine={agents_dir / 'steady.py'}:Steady"
    unit = json.loads((paper_root / "units" / "eval" / f"mine-main-{SEED}" / "unit.json").read_text())
    source = hashlib.sha256((agents_dir / "steady.py").read_bytes()).hexdigest()
    assert unit["agent"] == {"spec": spec, "kind": "file", "args": {"level": 0.2}, "sha256": {"source": source}}
    unit = json.loads((paper_root / "units" / "eval" / f"hold-llm-{SEED}" / "unit.json").read_text())
    module = hashlib.sha256((agents_dir / f"{MODULE}.py").read_bytes()).hexdigest()
    assert unit["agent"]["spec"] == f"{MODULE}:hold" and unit["agent"]["sha256"] == {"source": module}
    meta = json.loads((paper_root / "paper_metadata.json").read_text())
    assert meta["complete"] and meta["grid"]["agents"] == {"mine": spec, "hold": f"{MODULE}:hold"}
    assert meta["grid"]["settings"] == {"main": ["static", "mine", "hold"], "llm": ["mine", "hold"]}


def test_a_grid_unit_of_a_user_agent_equals_evaluate_of_the_same_spec(paper_root, agents_dir, tiny_dataset, tmp_path):
    out = tmp_path / "run"
    spec = f"mine={agents_dir / 'steady.py'}:Steady"
    result = invoke(
        ["evaluate", "--data", str(tiny_dataset), "--policies", spec, "--agent-arg", "mine.level=0.2"]
        + ["--seeds", str(SEED), "--episodes", "2", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    unit = pd.read_csv(paper_root / "units" / "eval" / f"mine-main-{SEED}" / "metrics.csv")
    pd.testing.assert_frame_equal(unit, pd.read_csv(out / "metrics.csv"))
    # --agent-arg reached the worker: level 0.2 is not the class's default 0.5
    default = pd.read_csv(paper_root / "units" / "eval" / f"hold-main-{SEED}" / "actions.csv")
    steady = pd.read_csv(paper_root / "units" / "eval" / f"mine-main-{SEED}" / "actions.csv")
    assert steady["reward_ratio"].nunique() == 1 and steady["reward_ratio"][0] != default["reward_ratio"][0]


def test_the_report_shows_user_agents_as_such_and_not_pooled_as_rl(paper_root):
    tables = paper_root / "report" / "tables"
    main = pd.read_csv(tables / "main_performance.csv")
    assert list(main["policy"]) == ["Static", "hold (user agent)", "mine (user agent)"]  # others by name
    tests = pd.read_csv(tables / "statistical_tests.csv")
    main_tests = tests[tests["setting"] == "Main"]["comparison"].tolist()
    assert main_tests == ["hold (user agent) vs Static", "mine (user agent) vs Static"]  # no "RL vs non-RL"
    learned = pd.read_csv(tables / "four_setting_learned.csv")
    assert set(learned["policy"]) == {"mine (user agent)", "hold (user agent)"}
    assert not (tables / "four_setting_aggregate.csv").exists()  # pools PPO, SAC, DQN only


def test_paper_resume_skips_user_agent_units_and_redoes_those_whose_agent_changed(paper_root, tiny_dataset, agents_dir):
    stamps = {p: p.stat().st_mtime_ns for p in paper_root.glob("units/eval/*/metrics.csv")}
    again = invoke(_paper(paper_root, tiny_dataset, agents_dir, "--agent-arg", "mine.level=0.2", "--no-report"))
    assert again.exit_code == 0, again.output
    assert "5 of 5 units already done: skipped" in again.output
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    # another --agent-arg for mine: its two units are redone, the others kept
    changed = invoke(_paper(paper_root, tiny_dataset, agents_dir, "--agent-arg", "mine.level=0.3", "--no-report"))
    assert changed.exit_code == 0, changed.output
    assert "3 of 5 units already done: skipped" in changed.output
    redone = {p.parent.name for p in stamps if p.stat().st_mtime_ns != stamps[p]}
    assert redone == {f"mine-main-{SEED}", f"mine-llm-{SEED}"}
    unit = json.loads((paper_root / "units" / "eval" / f"mine-llm-{SEED}" / "unit.json").read_text())
    assert unit["agent"]["args"] == {"level": 0.3}


def test_governance_runs_user_agents_behind_every_combination(tiny_dataset, agents_dir, tmp_path):
    out = tmp_path / "board"
    result = invoke(
        ["governance", "--data", str(tiny_dataset), "--seeds", "5", "--episodes", "1", "--out", str(out)]
        + ["--policies", f"static,mine={agents_dir / 'steady.py'}:Steady,{MODULE}:hold"]
        + ["--agent-arg", "mine.level=0.2", "--auditors", "rule,approve-only", "--resamples", "100"]
    )
    assert result.exit_code == 0, result.output
    meta = json.loads((out / "governance_metadata.json").read_text())
    assert meta["policies"] == ["static", "mine", "hold"]
    for slug in ("rule--rule", "rule--approve-only"):
        metrics = pd.read_csv(out / "runs" / "llm" / slug / "metrics.csv")
        assert list(metrics["policy"]) == ["static", "mine", "hold"] and (metrics["setting"] == "llm").all()
    board = pd.read_csv(out / "leaderboard_by_policy.csv")
    assert sorted(board["policy"].unique()) == ["hold", "mine", "static"] and len(board) == 6


SWEEP = """
grid:
  timesteps: 10
  episodes: 1
  seeds: [7]
  settings: [main, no_physics]
  policies:
    main: [static, "mine=agents/steady.py:Steady", "{module}:hold"]
    no_physics: ["{module}:hold"]
  agent_args: {{mine.level: 0.2}}
dataset:
  data: {data}
axes:
  lambda_p: [0.0, 2.0]
"""


def test_sweep_runs_user_agents_in_the_settings_that_list_them(tiny_dataset, agents_dir, tmp_path):
    # the file path is relative to the YAML, like dataset.data
    (tmp_path / "agents").mkdir()
    (tmp_path / "agents" / "steady.py").write_text(AGENT_FILE, encoding="utf-8")
    path = tmp_path / "sweep.yaml"
    path.write_text(SWEEP.format(module=MODULE, data=tiny_dataset), encoding="utf-8")
    root = tmp_path / "out"
    result = invoke(["sweep", str(path), "--out", str(root)])
    assert result.exit_code == 0, result.output
    results = pd.read_csv(root / "results.csv")
    for point in ("lambda_p-0.0", "lambda_p-2.0"):
        rows = results[results["point"] == point]
        assert list(rows[rows["setting"] == "main"]["policy"]) == ["static", "mine", "hold"]
        assert list(rows[rows["setting"] == "no_physics"]["policy"]) == ["hold"]
    # the reward weight reached the user agent's episodes (lambda_p 0 vs 2: same actions, other reward)
    mine = results[results["policy"] == "mine"].set_index("point")["cumulative_reward"]
    assert mine["lambda_p-0.0"] > mine["lambda_p-2.0"]
    unit = json.loads((root / "points" / "lambda_p-0.0" / "units" / "eval" / "mine-main-7" / "unit.json").read_text())
    assert unit["agent"]["spec"] == f"mine={tmp_path / 'agents' / 'steady.py'}:Steady"
    assert unit["agent"]["args"] == {"level": 0.2}
    again = invoke(["sweep", str(path), "--out", str(root)])
    assert again.exit_code == 0 and "8 units, 8 already done (skipped)" in again.output
    # grid.isolate: the same root resumes (its identity is unchanged) and redoes the user agents' units
    path.write_text(SWEEP.format(module=MODULE, data=tiny_dataset).replace("grid:\n", "grid:\n  isolate: true\n"))
    isolated = invoke(["sweep", str(path), "--out", str(root)])
    assert isolated.exit_code == 0 and "8 units, 2 already done (skipped)" in isolated.output, isolated.output
    unit_dir = root / "points" / "lambda_p-2.0" / "units" / "eval" / "hold-no_physics-7"
    assert json.loads((unit_dir / "run_metadata.json").read_text())["policy_access"] == {"hold": "isolated"}


@pytest.mark.parametrize(
    ("policies", "message"),
    [
        ("myopic,static=steady.py:Steady", "'static' is reserved for the benchmark's own 'static'"),
        (f"{MODULE}:Myopic", "'Myopic' is reserved for the benchmark's own 'myopic'"),
        ("a=steady.py:Steady,A=steady.py:Steady", "differ only in case"),
        (f"{MODULE}:wrong", "action"),
        ("steady.py:Nope", "has no attribute 'Nope'"),
        ("no_such_module_xyz:f", "cannot import 'no_such_module_xyz'"),
        ("fast=ppo", "under its own name"),
    ],
)
def test_paper_refuses_a_bad_agent_before_any_work(policies, message, tiny_dataset, agents_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(agents_dir)
    root = tmp_path / "root"
    result = invoke(
        ["paper", "--preset", "smoke", "--out", str(root), "--data", str(tiny_dataset), "--settings", "main"]
        + ["--policies", policies]
    )
    assert result.exit_code == 2, result.output
    assert message in result.output and len(result.output.strip().splitlines()) == 1
    assert not root.exists()


def test_governance_and_sweep_refuse_a_bad_agent_before_any_work(tiny_dataset, agents_dir, tmp_path):
    board = tmp_path / "board"
    result = invoke(
        ["governance", "--data", str(tiny_dataset), "--policies", f"{MODULE}:wrong", "--out", str(board)]
        + ["--seeds", "5", "--episodes", "1"]
    )
    assert result.exit_code == 2 and "wrong" in result.output and not board.exists()
    path = tmp_path / "sweep.yaml"
    root = tmp_path / "out"
    (tmp_path / "agents").mkdir()
    (tmp_path / "agents" / "steady.py").write_text(AGENT_FILE, encoding="utf-8")
    path.write_text(SWEEP.format(module="no_such_module_xyz", data=tiny_dataset), encoding="utf-8")
    result = invoke(["sweep", str(path), "--out", str(root)])
    assert result.exit_code == 2 and "grid.policies" in result.output and "no_such_module_xyz" in result.output
    assert not root.exists()
    # a wrong action shape shows on the sweep's dataset, still before any point or unit
    text = SWEEP.format(module=MODULE, data=tiny_dataset).replace(f"{MODULE}:hold", f"{MODULE}:wrong")
    path.write_text(text, encoding="utf-8")
    result = invoke(["sweep", str(path), "--out", str(root)])
    assert result.exit_code == 2 and "on the dataset" in result.output and "wrong" in result.output
    assert not (root / "points").exists()


def test_paper_isolate_runs_user_agents_in_their_own_process_from_the_workers(
    paper_root, tiny_dataset, agents_dir, tmp_path
):
    # --workers 2: the units run in the pool's worker processes, which start the agents' processes
    root = tmp_path / "isolated"
    args = _paper(root, tiny_dataset, agents_dir, "--agent-arg", "mine.level=0.2", "--no-report")
    args[args.index("main,llm")] = "main"
    result = invoke([*args, "--isolate", "--workers", "2"])
    assert result.exit_code == 0, result.output
    for name in ("mine", "hold", "static"):
        unit = root / "units" / "eval" / f"{name}-main-{SEED}"
        access = json.loads((unit / "run_metadata.json").read_text())["policy_access"]
        assert access == {name: "in-process" if name == "static" else "isolated"}  # built-ins stay in-process
        if name != "mine":  # an honest agent's rows are the in-process grid's, bit for bit (mine's args changed there)
            pd.testing.assert_frame_equal(
                pd.read_csv(unit / "actions.csv"),
                pd.read_csv(paper_root / "units" / "eval" / unit.name / "actions.csv"),
            )
    assert json.loads((root / "units" / "eval" / f"mine-main-{SEED}" / "unit.json").read_text())["isolate"] is True
    # the same grid without --isolate redoes the user agents' units (their door changed), not Static's
    again = invoke([*args, "--workers", "2"])
    assert again.exit_code == 0, again.output
    assert "1 of 3 units already done: skipped" in again.output
    access = json.loads((root / "units" / "eval" / f"mine-main-{SEED}" / "run_metadata.json").read_text())
    assert access["policy_access"] == {"mine": "in-process"}


PID_AGENT = """
import os


class Where:
    def __init__(self, report):
        self.report = report

    def act(self, observation):
        with open(self.report, "a") as out:
            out.write(f"{os.getpid()}\\n")
        return [0.5, 0.0, 0.5]
"""


def test_no_file_of_a_grid_records_an_agents_credentials(tiny_dataset, agents_dir, tmp_path):
    root, secret = tmp_path / "root", "sk-grid-secret-1234"
    url = "http://user:hunter2pass@127.0.0.1:9/act?token=tok-5678"
    args = _paper(root, tiny_dataset, agents_dir, "--agent-arg", f"keyed.api_token={secret}", "--no-report")
    args[args.index("main,llm")] = "main"
    args[args.index("--policies") + 1] = f"static,keyed={agents_dir / 'steady.py'}:Keyed"
    result = invoke(args)
    assert result.exit_code == 0, result.output
    unit = json.loads((root / "units" / "eval" / f"keyed-main-{SEED}" / "unit.json").read_text())
    assert unit["agent"]["args"] == {"api_token": "[redacted]"}
    for path in root.rglob("*"):
        if path.is_file():
            assert secret.encode() not in path.read_bytes(), path
    from solarchain_eval.experiments.user_agents import agent_identity

    recorded = agent_identity("remote", f"remote={url}", {}, {})
    assert "hunter2pass" not in json.dumps(recorded) and "tok-5678" not in json.dumps(recorded)


def test_governance_isolate_runs_the_user_agent_in_a_process_of_its_own(tiny_dataset, tmp_path):
    (tmp_path / "where.py").write_text(PID_AGENT, encoding="utf-8")
    report, out = tmp_path / "pids.txt", tmp_path / "board"
    result = invoke(
        ["governance", "--data", str(tiny_dataset), "--seeds", "5", "--episodes", "1", "--out", str(out)]
        + ["--policies", f"static,where={tmp_path / 'where.py'}:Where", "--agent-arg", f"where.report={report}"]
        + ["--isolate", "--resamples", "100", "--auditors", "rule"]
    )
    assert result.exit_code == 0, result.output
    pids = set(report.read_text().split())
    assert pids and str(os.getpid()) not in pids  # built in its own process (a check run and the run: 2)
    # governed rows are privileged whatever the door: the Planner/Auditor layer is handed the env
    meta = json.loads((out / "runs" / "llm" / "rule--rule" / "run_metadata.json").read_text())
    assert meta["policy_access"] == {"static": "privileged", "where": "privileged"}
