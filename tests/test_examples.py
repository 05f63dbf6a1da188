"""The examples act, and the pages' command sequences run as written, one after the other.

Each example runs on the default dataset (the paper's) with a tiny budget: the worked agent of
examples/my_agent.py, the HTTP example's rule, the SB3 train-then-evaluate script and the
notebook's code cells (executed with plain Python). The README's and the "Your agent" pages'
snippets run in order in one folder, so a snippet that reuses a run directory, or reads one no
earlier snippet wrote, fails here.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
TINY = ["--seeds", "20260511", "--episodes", "1"]  # the pages' commands at a budget of seconds


def _module(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _executed(result) -> dict[str, set[tuple[float, float, float]]]:
    """Each policy's distinct executed actions."""
    seen: dict[str, set] = {}
    for episode in result.episodes:
        steps = episode.steps
        actions = zip(steps["reward_ratio"], steps["liquidity_ratio"], steps["burn_rate"], strict=True)
        seen.setdefault(episode.policy, set()).update(actions)
    return seen


def test_worked_agent_takes_each_of_its_actions_on_the_default_data(published_dir):
    import solarchain_eval

    cautious = _module(EXAMPLES / "my_agent.py").Cautious
    result = solarchain_eval.evaluate(cautious(), data=published_dir, seeds=[20260511], episodes=2)
    # three rules, three actions: a threshold outside the data's range would leave one or two
    assert len(_executed(result)["Cautious"]) == 3


def test_worked_agent_is_the_one_on_the_page():
    page = (ROOT / "docs" / "evaluate_your_agent.md").read_text(encoding="utf-8")
    source = (EXAMPLES / "my_agent.py").read_text(encoding="utf-8")
    assert f"```python\n{source}```" in page


def test_http_example_rule_takes_both_branches_on_the_default_data(published_dir):
    from solarchain_eval.envs.env import SolarChainEnv

    decide = _module(EXAMPLES / "http_agent_server.py").decide
    env = SolarChainEnv(published_dir)
    names = env.observation_names
    obs, _ = env.reset(seed=20260511)
    answers = set()
    for _ in range(24):
        answers.add(tuple(decide(dict(zip(names, obs.tolist(), strict=True)))))
        obs, *_ = env.step(np.array([0.25, 0.75, 0.1], dtype=np.float32))
    assert {a[0] for a in answers} == {0.2, 0.5}  # short of spare supply in some hours, not in others
    assert {a[2] for a in answers} == {0.8, 0.1}  # many violating records in some hours, not in others


def test_sb3_example_trains_then_evaluates_beside_the_baselines(published_dir, tmp_path, capsys):
    script = _module(EXAMPLES / "train_sb3_then_evaluate.py")
    out = tmp_path / "my-ppo"
    table = script.main(["--timesteps", "128", "--data", str(published_dir), "--out", str(out), *TINY])
    assert list(table["policy"]) == ["my_ppo", "static", "myopic"]
    assert (out / "metrics.csv").is_file() and "protocol id:" in capsys.readouterr().out


def test_notebook_code_cells_run(published_dir, monkeypatch):
    notebook = json.loads((EXAMPLES / "quickstart.ipynb").read_text(encoding="utf-8"))
    cells = ["".join(c["source"]) for c in notebook["cells"] if c["cell_type"] == "code"]
    assert len(cells) >= 3
    monkeypatch.chdir(EXAMPLES)  # the notebook runs from examples/ (it imports my_agent beside it)
    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    # an earlier test may have imported another my_agent (a plugin test's own file): import this one
    monkeypatch.delitem(sys.modules, "my_agent", raising=False)
    namespace: dict = {"__name__": "notebook"}
    try:
        for number, cell in enumerate(cells):
            exec(compile(cell, f"quickstart.ipynb (code cell {number})", "exec"), namespace)
    finally:
        sys.modules.pop("my_agent", None)  # the next test imports examples/my_agent.py by path
    # the notebook's last cell counts the agent's distinct actions in the episode it plots
    assert namespace["episode"].policy == "Cautious" and namespace["distinct"] > 1
    assert len(_executed(namespace["result"])["Cautious"]) > 1


# --- the pages' sequences ---------------------------------------------------------------------


def _blocks(text: str) -> list[tuple[str, str]]:
    return re.findall(r"^```(python|bash)\n(.*?)\n```$", text, re.S | re.M)


def _commands(block: str) -> list[list[str]]:
    """The ``solarchain-eval`` command lines of a bash block (continuations joined)."""
    joined = block.replace("\\\n", " ")
    return [shlex.split(line)[1:] for line in joined.splitlines() if line.startswith("solarchain-eval ")]


def _run_sequence(blocks: list[tuple[str, str]], where: str) -> int:
    from typer.testing import CliRunner

    from solarchain_eval.cli import app

    ran = 0
    for language, block in blocks:
        if language == "python":
            # the paper's protocol in Python snippets too, cut to the tiny budget
            code = block.replace("evaluate([", "evaluate(seeds=[20260511], episodes=1, agent=[")
            exec(compile(code, where, "exec"), {"__name__": "snippet"})
            ran += 1
            continue
        for args in _commands(block):
            if args[0] == "evaluate":
                args = [*args, *TINY]
            elif args[0] == "report":
                args = [*args, "--no-figures", "--resamples", "100"]
            result = CliRunner().invoke(app, args)
            assert result.exit_code == 0, f"{where}: solarchain-eval {shlex.join(args)}\n{result.output}"
            ran += 1
    return ran


@pytest.fixture
def in_a_fresh_folder(tmp_path, monkeypatch, published_dir):
    (tmp_path / "examples").symlink_to(EXAMPLES)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_readme_agent_snippets_run_in_sequence(in_a_fresh_folder):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    section = readme.split("## Evaluate your agent", 1)[1].split("\n## ", 1)[0]
    assert _run_sequence(_blocks(section), "README.md (Evaluate your agent)") == 3
    assert (in_a_fresh_folder / "runs" / "mine-python" / "metrics.csv").is_file()
    assert (in_a_fresh_folder / "runs" / "mine" / "report").is_dir()


def test_your_agent_pages_run_in_sequence(in_a_fresh_folder, capsys):
    docs = ROOT / "docs"
    evaluate_page = (docs / "evaluate_your_agent.md").read_text(encoding="utf-8")
    door1 = evaluate_page.split("## Door 1: Python", 1)[1].split("\n## ", 1)[0]
    worked = evaluate_page.split("## A worked example", 1)[1].split("\n## ", 1)[0]
    study = (docs / "study_your_agent.md").read_text(encoding="utf-8")
    ran = _run_sequence(_blocks(door1), "evaluate_your_agent.md (door 1)")
    ran += _run_sequence([b for b in _blocks(worked) if b[0] == "bash"], "evaluate_your_agent.md (worked example)")
    ran += _run_sequence(_blocks(study), "study_your_agent.md")
    assert ran == 5
    out = capsys.readouterr().out
    assert "Cautious" in out and "Beijing" in out  # the study read the worked example's run


def test_sequence_runner_catches_a_reused_run_directory(in_a_fresh_folder):
    """The guard itself: two evaluations into one --out fail, as they would for a reader."""
    block = "solarchain-eval evaluate --policies static --out runs/x\nsolarchain-eval evaluate --policies random --out runs/x"
    with pytest.raises(AssertionError, match="already holds"):
        _run_sequence([("bash", block)], "planted")
    assert os.path.isdir("runs/x")


def test_http_page_runs_in_sequence_against_the_example_server(in_a_fresh_folder):
    import subprocess

    page = (ROOT / "docs" / "http_agents.md").read_text(encoding="utf-8")
    quick = page.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    server = subprocess.Popen(
        [sys.executable, str(EXAMPLES / "http_agent_server.py"), "--port", "0"], stdout=subprocess.PIPE, text=True
    )
    try:
        url = server.stdout.readline().split()[-1]
        blocks = [(language, block.replace("http://127.0.0.1:8000/act", url)) for language, block in _blocks(quick)]
        assert _run_sequence(blocks, "http_agents.md (quick start)") == 2
    finally:
        server.terminate()
        server.wait(timeout=10)
    assert (in_a_fresh_folder / "runs" / "mine" / "metrics.csv").is_file()
    assert (in_a_fresh_folder / "runs" / "mine-python" / "metrics.csv").is_file()
