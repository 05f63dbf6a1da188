"""The agent door under an adversary: records an agent cannot write, names it cannot take, actions
it cannot have repaired, and user-code failures that are one line (exit status 2, nothing published)."""

from __future__ import annotations

import json
import textwrap
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from solarchain_eval.agents.adapters import AgentError, AgentFailure
from solarchain_eval.agents.names import NAME_RULE
from solarchain_eval.agents.registry import EXTRA_POLICIES
from solarchain_eval.agents.specs import LLM_AGENT, AgentSpecError
from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.data.table import load_table
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.evaluation.reserved import reserved_names
from solarchain_eval.governance.auditor import AUDITOR_KINDS
from solarchain_eval.governance.planner import PLANNER_KINDS
from solarchain_eval.market.baselines import BASELINES

SEED = 20260511


class Honest:
    """Acts like a cautious operator; the attackers below only add what their hooks return."""

    name = "honest"

    def act(self, observation):
        return np.array([0.3, 0.7, 0.05], dtype=np.float32)


class Liar(Honest):
    name = "liar"

    def __init__(self, returned):
        self.returned = returned

    def end_episode(self):
        return self.returned


def _evaluate(agent, tiny_dataset: Path, **options):
    return solarchain_eval.evaluate(agent, data=tiny_dataset, seeds=[SEED], episodes=2, **options)


# --- 3. Agents cannot write records -----------------------------------------------------------------


def test_what_end_episode_returns_lands_in_its_own_agent_columns_only(tiny_dataset: Path, tmp_path: Path) -> None:
    honest = _evaluate(Honest(), tiny_dataset, name="liar").metrics
    attack = {"cumulative_reward": 1e6, "physics_violation_rate": 0, "policy": "static", "episode": 7, "ok": True}
    _evaluate(Liar(attack), tiny_dataset, out=tmp_path / "run")
    written = pd.read_csv(tmp_path / "run" / "metrics.csv")
    # the runner's columns are the honest run's, bit for bit
    runner_columns = [c for c in honest.columns if not c.startswith("agent_")]
    pd.testing.assert_frame_equal(written[runner_columns], honest[runner_columns], check_exact=True)
    assert set(written["policy"]) == {"liar"} and list(written["episode"]) == [0, 1]
    assert (written["cumulative_reward"] < 1e3).all()
    # what the agent returned is kept, in its own namespace
    assert list(written["agent_cumulative_reward"]) == [1e6, 1e6]
    assert list(written["agent_policy"]) == ["static", "static"]
    assert list(written["agent_ok"]) == [1, 1]
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert [entry["policy"] for entry in summary] == ["liar"]  # nothing pooled with the real baseline


def test_under_the_planner_auditor_layer_the_layers_columns_stay_its_own(tiny_dataset: Path) -> None:
    metrics = _evaluate(Liar({"planner": "mine", "audit_rate": 0.0}), tiny_dataset, setting="llm").metrics
    assert set(metrics["planner"]) == {"rule"}
    assert list(metrics["agent_planner"]) == ["mine", "mine"]
    assert list(metrics["agent_audit_rate"]) == [0.0, 0.0]


@pytest.mark.parametrize(
    ("returned", "problem"),
    [
        ({"agentic_metrics": {"cumulative_reward": 1e6}}, "end_episode() 'agentic_metrics' is dict"),
        ({"score": float("nan")}, "end_episode() 'score' is nan; numbers must be finite"),
        ({"score": float("inf")}, "end_episode() 'score' is inf; numbers must be finite"),
        ({"note": "two\nlines"}, "end_episode() 'note': text must be one line"),
        ({"bad key": 1}, "end_episode() key 'bad key'"),
        ([1, 2], "end_episode() returned list [1, 2]; return None or a dict"),
    ],
)
def test_an_end_episode_value_that_is_not_numbers_and_short_text_is_refused(
    tiny_dataset: Path, tmp_path: Path, returned, problem: str
) -> None:
    with pytest.raises(AgentFailure) as caught:
        _evaluate(Liar(returned), tiny_dataset, out=tmp_path / "run")
    assert str(caught.value).startswith(f"agent 'liar': {problem}")
    assert str(caught.value).endswith(f"(run seed {SEED}, episode 0, step 23)")
    assert not (tmp_path / "run").exists()


# --- 5. Names ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", ["a/b", "<script>", "a\nb", "a,b", "a b", "", "x" * 65, "-lead"])
def test_python_names_follow_the_command_lines_rule(tiny_dataset: Path, tmp_path: Path, bad: str) -> None:
    with pytest.raises(AgentSpecError, match="letters, digits"):
        _evaluate(Honest(), tiny_dataset, name=bad, out=tmp_path / "run")
    with pytest.raises(AgentSpecError, match="letters, digits"):
        _evaluate("static", tiny_dataset, name=bad, out=tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_an_agents_own_name_follows_the_rule_too(tiny_dataset: Path) -> None:
    class Spaced(Honest):
        name = "my agent"

    with pytest.raises(AgentError, match="'my agent'.*letters, digits"):
        _evaluate(Spaced(), tiny_dataset)
    with pytest.raises(AgentError, match="'<lambda>'.*name="):
        _evaluate(lambda observation: [0.3, 0.7, 0.05], tiny_dataset)
    assert _evaluate(Honest(), tiny_dataset, name="x" * 64).metrics["policy"].iloc[0] == "x" * 64


def test_the_cli_refuses_the_same_names(tiny_dataset: Path, tmp_path: Path) -> None:
    for bad in ("<script>", "a\nb"):
        result = _cli(tiny_dataset, tmp_path, f"{bad}=static")
        assert result.exit_code == 2, result.output
        assert NAME_RULE in " ".join(result.output.split())


def test_reserved_names_come_from_the_registries() -> None:
    expected = {*BASELINES, *EXTRA_POLICIES, LLM_AGENT, *PLANNER_KINDS, *AUDITOR_KINDS}
    assert set(reserved_names()) == expected
    assert {"static", "random", "myopic", "ppo", "sac", "dqn", "ppo-lag", "llm-agent", "rule", "oracle"} <= expected


@pytest.mark.parametrize("name", ["static", "Static", "MYOPIC", "ppo", "ppo-lag", "llm-agent", "rule", "oracle"])
def test_a_user_agent_cannot_take_a_built_in_name(tiny_dataset: Path, tmp_path: Path, name: str) -> None:
    with pytest.raises(AgentSpecError, match=f"agent name '{name}' is reserved"):
        _evaluate(Honest(), tiny_dataset, name=name, out=tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_the_benchmarks_own_policy_objects_keep_their_names(tiny_dataset: Path) -> None:
    import importlib

    from solarchain_eval.agents.adapters import BUILTIN_POLICY_CLASSES, is_builtin_policy
    from solarchain_eval.market.baselines import make_baseline

    for qualified in BUILTIN_POLICY_CLASSES:  # the list names real classes
        module, _, name = qualified.rpartition(".")
        assert isinstance(getattr(importlib.import_module(module), name), type), qualified
    static = make_baseline("static")
    assert is_builtin_policy(static) and not is_builtin_policy(_named(Honest(), "static"))
    assert list(_evaluate([static, Honest()], tiny_dataset).summary["policy"]) == ["static", "honest"]


def test_on_the_command_line_neither(tiny_dataset: Path, tmp_path: Path, agent_file: Path) -> None:
    for policies in (f"static={agent_file}:Constant", "random=static", "Static=myopic", f"{agent_file}:Rule"):
        result = _cli(tiny_dataset, tmp_path, policies)
        assert result.exit_code == 2, (policies, result.output)
        assert "is reserved for the benchmark's own" in result.output
        assert not (tmp_path / "run").exists()
    result = _cli(tiny_dataset, tmp_path, f"static,mine=myopic,{agent_file}:Constant")
    assert result.exit_code == 0, result.output
    assert list(dict.fromkeys(pd.read_csv(tmp_path / "run" / "metrics.csv")["policy"])) == [
        "static",
        "mine",
        "Constant",
    ]


def test_names_are_one_name_whatever_their_case_across_a_board(tiny_dataset: Path, tmp_path: Path) -> None:
    from solarchain_eval.report.leaderboard import make_leaderboards
    from solarchain_eval.report.leaderboard.inputs import LeaderboardError

    with pytest.raises(AgentSpecError, match="differ only in case"):
        _evaluate([_named(Honest(), "Mine"), _named(Honest(), "mine")], tiny_dataset)
    _evaluate(Honest(), tiny_dataset, name="Mine", out=tmp_path / "a")
    _evaluate(Liar(None), tiny_dataset, name="mine", out=tmp_path / "b")
    with pytest.raises(LeaderboardError, match="'mine' of .* and 'Mine' of .* differ only in case"):
        make_leaderboards([tmp_path / "a", tmp_path / "b"], tmp_path / "board")


def _named(agent, name):
    agent.name = name
    return agent


# --- 7. One rule for invalid actions ----------------------------------------------------------------


class BadFrom:
    """Acts well until (episode, step), then returns ``bad``."""

    name = "bad"

    def __init__(self, bad, episode=1, step=5, action_mode="continuous"):
        self.bad, self.when, self.action_mode = bad, (episode, step), action_mode
        self.good = 7 if action_mode == "discrete" else np.array([0.3, 0.7, 0.05], dtype=np.float32)

    def begin_episode(self, *, episode, **_context):
        self.episode, self.step = episode, 0

    def act(self, observation):
        self.step += 1
        return self.bad if (self.episode, self.step - 1) == self.when else self.good


@pytest.mark.parametrize(
    ("bad", "problem"),
    [
        ([float("nan"), 0.5, 0.5], "act() returned action[0]=nan, which is not finite"),
        ([0.5, float("inf"), 0.5], "act() returned action[1]=inf, which is not finite"),
        ([0.5, 0.5, -float("inf")], "act() returned action[2]=-inf, which is not finite"),
        ([0.5, 1.5, 0.5], "act() returned action[1]=1.5, outside [0, 1]"),
        ([-0.01, 0.5, 0.5], "act() returned action[0]=-0.01, outside [0, 1]"),
        (["0.5", "0.5", "0.5"], "act() returned ['0.5', '0.5', '0.5']; a continuous action is three numbers"),
        ([0.5, 0.5], "act() returned an action of shape (2,)"),
        (None, "act() returned None;"),
    ],
)
def test_an_invalid_action_is_refused_naming_agent_run_seed_episode_and_step(
    tiny_dataset: Path, tmp_path: Path, bad, problem: str
) -> None:
    with pytest.raises(AgentFailure) as caught:
        _evaluate(BadFrom(bad), tiny_dataset, out=tmp_path / "run")
    message = str(caught.value)
    assert message.startswith(f"agent 'bad': {problem}"), message
    assert message.endswith(f"(run seed {SEED}, episode 1, step 5)")
    assert "\n" not in message
    assert not (tmp_path / "run").exists()


def test_a_discrete_index_outside_the_grid_is_refused(tiny_dataset: Path, tmp_path: Path) -> None:
    for bad, problem in ((125, "the index 125, outside 0..124"), (-1, "the index -1"), (3.0, "one integer index")):
        with pytest.raises(AgentFailure) as caught:
            _evaluate(BadFrom(bad, episode=0, step=7, action_mode="discrete"), tiny_dataset, out=tmp_path / "r")
        assert problem in str(caught.value)
        assert str(caught.value).endswith(f"(run seed {SEED}, episode 0, step 7)")
    assert not (tmp_path / "r").exists()


def test_a_governed_user_agent_is_held_to_the_same_rule(tiny_dataset: Path) -> None:
    with pytest.raises(AgentFailure, match=r"action\[0\]=nan.*\(run seed \d+, episode 1, step 5\)"):
        _evaluate(BadFrom([float("nan"), 0.5, 0.5]), tiny_dataset, setting="llm")


def test_the_benchmarks_own_policies_renamed_keep_the_environments_decoding(tiny_dataset: Path, monkeypatch) -> None:
    # A built-in's action (a learned policy's raw output, say) is not a user's: the env clips it as
    # it always did, also when the built-in is renamed (mine=static).
    class Overshoots:
        name, action_mode = "static", "continuous"

        def act(self, observation):
            return np.array([1.5, -0.25, 0.5], dtype=np.float32)

    monkeypatch.setattr("solarchain_eval.solar.task.make_baseline", lambda name, market: Overshoots())
    result = _evaluate(["mine=static"], tiny_dataset)
    steps = result.episodes[0].steps
    executed = [steps[c][0] for c in ("reward_ratio", "liquidity_ratio", "burn_rate")]
    env = SolarChainEnv(config=BenchmarkConfig(), table=load_table(tiny_dataset))
    np.testing.assert_array_equal(executed, env.codec.decode(np.array([1.0, 0.0, 0.5], dtype=np.float32)))
    with pytest.raises(AgentFailure, match="action\\[0\\]=1.5, outside"):
        _evaluate(Overshoots(), tiny_dataset, name="mine")  # the same object from a user is refused


# --- 8. Every user-code failure is one line ---------------------------------------------------------

ATTACK_FILE = textwrap.dedent(
    """
    import sys

    import numpy as np


    class Constant:
        def act(self, observation):
            return np.array([0.3, 0.7, 0.05], dtype=np.float32)


    class Rule(Constant):
        pass


    class Boom(Constant):
        def __init__(self, at=0):
            self.at, self.steps = at, 0

        def act(self, observation):
            self.steps += 1
            if self.steps > self.at:
                raise RuntimeError("boom\\nsecond line")
            return super().act(observation)


    class Quits(Constant):
        def act(self, observation):
            sys.exit(0)


    class Listy(Constant):
        def end_episode(self):
            return [1, 2]


    class Nan(Constant):
        stateless = True

        def act(self, observation):
            return np.array([0.3, float("nan"), 0.05])


    class Index(Constant):
        action_mode = "discrete"

        def act(self, observation):
            return 125
    """
)


@pytest.fixture
def agent_file(tmp_path: Path) -> Path:
    path = tmp_path / "agents" / "attacks.py"
    path.parent.mkdir()
    path.write_text(ATTACK_FILE)
    return path


def _cli(tiny_dataset: Path, tmp_path: Path, policies: str, *extra: str, env: dict | None = None, episodes: int = 1):
    args = ["evaluate", "--data", str(tiny_dataset), "--seeds", str(SEED), "--episodes", str(episodes)]
    return CliRunner().invoke(app, [*args, "--policies", policies, "--out", str(tmp_path / "run"), *extra], env=env)


def _one_line_exit_2(result, tmp_path: Path) -> str:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert not (tmp_path / "run").exists()
    return lines[0]


@pytest.mark.parametrize(
    ("target", "extra", "expected"),
    [
        # at the pre-flight step (a copy's first action)
        ("Boom", [], "agent 'Boom': act() raised RuntimeError: boom second line (run seed {seed}, episode 0, step 0)"),
        # mid-run: the copy passed, the real run fails at its second episode's fourth step
        (
            "Boom",
            ["--agent-arg", "at=27"],
            "agent 'Boom': act() raised RuntimeError: boom second line (run seed {seed}, episode 1, step 3)",
        ),
        ("Quits", [], "agent 'Quits': act() raised SystemExit(0): the agent called sys.exit"),
        ("Listy", [], "agent 'Listy': end_episode() returned list [1, 2]; return None or a dict"),
        ("Nan", [], "agent 'Nan': act() returned action[1]=nan, which is not finite"),
        (
            "Index",
            [],
            "agent 'Index': act() returned the index 125, outside 0..124 (run seed {seed}, episode 0, step 0)",
        ),
    ],
)
def test_user_code_failures_are_one_line_exit_2_and_nothing_published(
    tiny_dataset: Path, tmp_path: Path, agent_file: Path, target: str, extra: list[str], expected: str
) -> None:
    result = _cli(tiny_dataset, tmp_path, f"{agent_file}:{target}", *extra, episodes=2)
    line = _one_line_exit_2(result, tmp_path)
    assert expected.format(seed=SEED) in line, line


def test_an_agent_module_that_exits_at_import_is_an_error_not_a_silent_success(
    tiny_dataset: Path, tmp_path: Path
) -> None:
    path = tmp_path / "quitter.py"
    path.write_text("import sys\nsys.exit(0)\n")
    line = _one_line_exit_2(_cli(tiny_dataset, tmp_path, f"{path}:Agent"), tmp_path)
    assert f"running {path} raised SystemExit(0)" in line


def test_specs_and_out_paths_that_are_not_what_they_claim(tiny_dataset: Path, tmp_path: Path) -> None:
    line = _one_line_exit_2(_cli(tiny_dataset, tmp_path, "../../../../../../etc/passwd:x"), tmp_path)
    assert "is not a Python file" in line
    (tmp_path / "run").write_text("mine")
    result = _cli(tiny_dataset, tmp_path, "static")
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert len(result.stderr.strip().splitlines()) == 1
    assert (tmp_path / "run").read_text() == "mine"


@pytest.mark.parametrize("command", [["report", "{run}"], ["leaderboard", "{run}"], ["paper", "--preset", "smoke"]])
def test_every_out_naming_an_existing_file_is_one_line(tiny_dataset: Path, tmp_path: Path, command) -> None:
    run = tmp_path / "published"
    _evaluate("static", tiny_dataset, out=run)
    (tmp_path / "file").write_text("mine")
    args = [part.format(run=run) for part in command]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "file")])
    assert result.exit_code == 2, result.output
    assert result.stderr.strip() == f"error: --out {tmp_path / 'file'} is an existing file, not a folder"
    assert (tmp_path / "file").read_text() == "mine"


def test_solarchain_debug_shows_the_users_traceback(tiny_dataset: Path, tmp_path: Path, agent_file: Path) -> None:
    result = _cli(tiny_dataset, tmp_path, f"{agent_file}:Boom", env={"SOLARCHAIN_DEBUG": "1"})
    assert result.exit_code == 2
    assert "Traceback" in result.stderr
    assert f'File "{agent_file.resolve()}"' in result.stderr and 'raise RuntimeError("boom' in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("error: agent 'Boom': act() raised RuntimeError")


class _FailsFromStep4(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def do_POST(self) -> None:
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
        status, reply = (200, {"action": [0.3, 0.7, 0.05]}) if body["step"] < 4 else (400, {"error": "tired"})
        data = json.dumps(reply).encode()
        self.send_response(status)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def log_message(self, *args: object) -> None:
        pass


def test_an_http_agent_failing_from_step_4_is_one_line(tiny_dataset: Path, tmp_path: Path) -> None:
    server = ThreadingHTTPServer(("127.0.0.1", 0), _FailsFromStep4)
    threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True).start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/act"
        line = _one_line_exit_2(_cli(tiny_dataset, tmp_path, f"tired={url}"), tmp_path)
    finally:
        server.shutdown()
        server.server_close()
    assert line.startswith(f"error: agent 'tired' ({url}): reply HTTP 400 Bad Request")
    assert line.endswith(f"(run seed {SEED}, episode 0, step 4)")
