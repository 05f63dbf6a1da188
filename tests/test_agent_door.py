"""The door for users' agents: the Python API, fairness, names, specs and the evaluate command."""

from __future__ import annotations

import hashlib
import json
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from solarchain_eval.agents.adapters import AgentError, as_agent
from solarchain_eval.agents.base import EPISODE_CONTEXT_KEYS, access_label, is_privileged
from solarchain_eval.agents.registry import parse_agents
from solarchain_eval.agents.specs import AgentSpecError, parse_agent_args
from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.data.table import load_table
from solarchain_eval.envs.env import SolarChainEnv
from solarchain_eval.evaluation.fingerprint import protocol_id
from solarchain_eval.evaluation.rollout import run_policy
from solarchain_eval.experiments.user_agents import agent_identity
from solarchain_eval.market.baselines import make_baseline

SEED = 20260511
STATIC_ACTION = None  # filled lazily: the Static baseline's encoded action


def static_action() -> np.ndarray:
    static = make_baseline("static", BenchmarkConfig().market)
    return np.asarray(static.act(np.zeros(1)), dtype=np.float32)


class Recorder:
    """A user agent that keeps every argument its hooks receive."""

    name = "recorder"

    def __init__(self) -> None:
        self.begin_calls: list[dict] = []
        self.infos: list[dict] = []
        self.runs: list[int] = []

    def begin_run(self, run_seed):
        self.runs.append(run_seed)

    def begin_episode(self, **context):
        self.begin_calls.append(context)

    def observe(self, info):
        self.infos.append(info)

    def act(self, observation):
        return [0.4, 0.6, 0.1]


def _reachable_env(value, env, depth=0) -> bool:
    """Whether ``env`` or its hourly table is reachable from ``value`` through containers/attributes."""
    if value is env or value is env.table or depth > 3:
        return value is env or value is env.table
    if isinstance(value, dict):
        return any(_reachable_env(v, env, depth + 1) for v in value.values())
    if isinstance(value, list | tuple):
        return any(_reachable_env(v, env, depth + 1) for v in value)
    return any(_reachable_env(v, env, depth + 1) for v in getattr(value, "__dict__", {}).values())


def test_hooks_get_the_public_context_and_never_the_env(tiny_dataset: Path) -> None:
    env = SolarChainEnv(config=BenchmarkConfig(), table=load_table(tiny_dataset))
    agent = Recorder()
    results = list(run_policy(env, as_agent(agent), setting="main", run_seeds=[SEED], episodes=2))
    assert agent.runs == [SEED]
    assert [sorted(c) for c in agent.begin_calls] == [sorted(EPISODE_CONTEXT_KEYS)] * 2
    assert [c["episode_seed"] for c in agent.begin_calls] == [SEED, SEED + 1]
    assert [c["start_hour"] for c in agent.begin_calls] == [r.start_hour for r in results]
    assert all(type(v) is int for c in agent.begin_calls for v in c.values())
    assert len(agent.infos) == 2 * env.episode_steps
    for argument in [*agent.begin_calls, *agent.infos]:
        assert not _reachable_env(argument, env)


def test_only_the_benchmarks_own_components_are_privileged() -> None:
    class Sneaky(Recorder):
        privileged = True  # a user's class cannot claim the env

    assert not is_privileged(Sneaky())
    assert access_label(Sneaky()) == "in-process"
    from solarchain_eval.governance.wrapper import GovernedPolicy

    assert GovernedPolicy.privileged and GovernedPolicy.__module__.startswith("solarchain_eval.")


def test_a_user_class_claiming_privilege_still_gets_no_env(tiny_dataset: Path) -> None:
    class Sneaky(Recorder):
        privileged = True

        def begin_episode(self, **context):
            assert "env" not in context
            super().begin_episode(**context)

    env = SolarChainEnv(config=BenchmarkConfig(), table=load_table(tiny_dataset))
    agent = Sneaky()
    list(run_policy(env, as_agent(agent), setting="main", run_seeds=[SEED], episodes=1))
    assert len(agent.begin_calls) == 1


def test_evaluate_a_function_an_object_and_a_baseline(tiny_dataset: Path, tmp_path: Path) -> None:
    action = static_action()

    def same_as_static(observation):
        return action

    result = solarchain_eval.evaluate(
        [same_as_static, Recorder(), "static"], data=tiny_dataset, seeds=[SEED], episodes=2, out=tmp_path / "run"
    )
    assert list(result.summary["policy"]) == ["same_as_static", "recorder", "static"]
    metrics = result.metrics.set_index(["policy", "episode"])
    # The function takes the Static baseline's action: every metric equals the baseline's, bit for bit.
    mine = metrics.loc["same_as_static"].drop(columns=["setting"])
    static = metrics.loc["static"].drop(columns=["setting"])
    pd.testing.assert_frame_equal(mine, static, check_exact=True)
    assert not np.allclose(metrics.loc["recorder"]["cumulative_reward"], static["cumulative_reward"])
    written = pd.read_csv(tmp_path / "run" / "metrics.csv")
    assert sorted(set(written["policy"])) == ["recorder", "same_as_static", "static"]
    meta = json.loads((tmp_path / "run" / "run_metadata.json").read_text())
    assert meta["protocol_id"] == result.protocol_id == protocol_id(meta["protocol"])
    assert meta["policy_access"] == {"same_as_static": "in-process", "recorder": "in-process", "static": "in-process"}


def test_evaluate_without_out_keeps_nothing(tiny_dataset: Path) -> None:
    result = solarchain_eval.evaluate(Recorder(), data=tiny_dataset, seeds=[SEED], episodes=1, name="mine")
    assert result.run_dir is None
    assert list(result.summary["policy"]) == ["mine"]


def test_two_agents_with_one_name_are_refused_before_anything_is_written(tiny_dataset: Path, tmp_path: Path) -> None:
    with pytest.raises(AgentSpecError, match="'recorder' is used twice"):
        solarchain_eval.evaluate(
            [Recorder(), Recorder()], data=tiny_dataset, seeds=[SEED], episodes=1, out=tmp_path / "r"
        )
    assert not (tmp_path / "r").exists()
    with pytest.raises(AgentSpecError, match="differ only in case"):
        parse_agents("static,Static=myopic")


def test_the_governed_setting_wraps_user_agents_and_labels_them_privileged(tiny_dataset: Path) -> None:
    agent = Recorder()
    result = solarchain_eval.evaluate(agent, data=tiny_dataset, seeds=[SEED], episodes=1, setting="llm")
    assert set(result.metrics["setting"]) == {"llm"}
    assert result.access == {"recorder": "privileged"}
    assert len(agent.begin_calls) == 1 and "env" not in agent.begin_calls[0]


def _executed_actions(result) -> np.ndarray:
    """The first episode's executed (α, ℓ, b) per step, one row each."""
    steps = result.episodes[0].steps
    return np.column_stack([np.asarray(steps[c]) for c in ("reward_ratio", "liquidity_ratio", "burn_rate")])


def test_sb3_model_objects_act_deterministically(tiny_dataset: Path) -> None:
    from stable_baselines3 import PPO

    env = SolarChainEnv(config=BenchmarkConfig(), table=load_table(tiny_dataset))
    model = PPO("MlpPolicy", env, seed=0, n_steps=64, batch_size=32, device="cpu")
    result = solarchain_eval.evaluate(model, data=tiny_dataset, seeds=[SEED], episodes=1, name="my-ppo")
    actions = _executed_actions(result)
    obs, _ = env.reset(seed=SEED)
    expected = env.codec.decode(model.predict(obs, deterministic=True)[0])
    np.testing.assert_allclose(actions[0], expected, rtol=0, atol=1e-7)


def test_recurrent_models_carry_their_state_through_an_episode(tiny_dataset: Path) -> None:
    from sb3_contrib import RecurrentPPO

    env = SolarChainEnv(config=BenchmarkConfig(), table=load_table(tiny_dataset))
    model = RecurrentPPO("MlpLstmPolicy", env, seed=0, n_steps=32, batch_size=32, device="cpu")
    result = solarchain_eval.evaluate(model, data=tiny_dataset, seeds=[SEED], episodes=1, name="lstm")
    executed = _executed_actions(result)
    obs, _ = env.reset(seed=SEED)
    state, start, expected = None, np.ones((1,), dtype=bool), []
    for _ in range(env.episode_steps):
        action, state = model.predict(obs, state=state, episode_start=start, deterministic=True)
        start = np.zeros((1,), dtype=bool)
        expected.append(env.codec.decode(action))
        obs, *_ = env.step(action)
    np.testing.assert_allclose(executed, np.array(expected), rtol=0, atol=1e-7)


def test_wrong_actions_are_one_line_errors(tiny_dataset: Path) -> None:
    with pytest.raises(AgentError, match=r"agent 'two': act\(\) returned an action of shape \(2,\)"):
        solarchain_eval.evaluate(lambda obs: [0.1, 0.2], name="two", data=tiny_dataset, seeds=[SEED], episodes=1)
    with pytest.raises(AgentError, match="cannot use int as an agent"):
        as_agent(3)


def test_agent_args_are_read_as_json_and_scoped() -> None:
    args = parse_agent_args(["alpha=0.5", "B.alpha=0.25", "label=plain text", "B.flags=[1, 2]"], ["B"])
    assert args == {None: {"alpha": 0.5, "label": "plain text"}, "B": {"alpha": 0.25, "flags": [1, 2]}}
    with pytest.raises(AgentSpecError, match="KEY=VALUE"):
        parse_agent_args(["alpha"], [])


AGENT_FILE = textwrap.dedent(
    """
    import numpy as np

    class Constant:
        def __init__(self, alpha=0.3):
            self.alpha = alpha

        def act(self, observation):
            return np.array([self.alpha, 0.7, 0.05], dtype=np.float32)

    def make(alpha=0.3):
        return Constant(alpha)

    def two_numbers(observation):
        return [0.1, 0.2]
    """
)


@pytest.fixture
def agent_file(tmp_path: Path) -> Path:
    path = tmp_path / "agents" / "my_agent.py"
    path.parent.mkdir()
    path.write_text(AGENT_FILE)
    return path


def _evaluate(args: list[str]):
    return CliRunner().invoke(app, ["evaluate", "--episodes", "1", "--seeds", str(SEED), *args])


def test_cli_file_specs_keep_case_and_take_agent_args(tiny_dataset: Path, agent_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    policies = f"static,{agent_file}:Constant,B={agent_file}:make"
    result = _evaluate(
        ["--data", str(tiny_dataset), "--policies", policies, "--agent-arg", "B.alpha=0.5", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    metrics = pd.read_csv(out / "metrics.csv")
    assert list(dict.fromkeys(metrics["policy"])) == ["static", "Constant", "B"]
    actions = pd.read_csv(out / "actions.csv")
    alpha = actions.groupby("policy")["reward_ratio"].first()
    codec = SolarChainEnv(config=BenchmarkConfig(), table=load_table(tiny_dataset)).codec
    assert alpha["B"] == pytest.approx(codec.decode([0.5, 0.7, 0.05])[0], abs=1e-7)  # the factory got alpha=0.5
    assert alpha["Constant"] == pytest.approx(codec.decode([0.3, 0.7, 0.05])[0], abs=1e-7)  # the default
    assert "protocol " in result.output


@pytest.mark.parametrize(
    ("policies", "extra", "message"),
    [
        ("{file}:missing", [], "has no attribute 'missing'"),
        ("{file}:two_numbers", [], "act() returned an action of shape (2,)"),
        ("no_such_module_xyz:Agent", [], "cannot import 'no_such_module_xyz'"),
        ("{file}:Constant", ["--agent-arg", "beta=1"], "does not accept ['beta']"),
        ("x={file}:Constant,x=static", [], "'x' is used twice"),
        ("nonsense", [], "unknown policy 'nonsense'"),
        ("mine=sb3:NoSuchAlgo:{file}", [], "unknown SB3 algorithm 'NoSuchAlgo'"),
    ],
)
def test_cli_bad_specs_fail_in_one_line_before_any_work(
    tiny_dataset: Path, agent_file: Path, tmp_path: Path, policies: str, extra: list[str], message: str
) -> None:
    out = tmp_path / "run"
    result = _evaluate(
        ["--data", str(tiny_dataset), "--policies", policies.format(file=agent_file), *extra, "--out", str(out)]
    )
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output
    assert not out.exists()


def test_sb3_spec_any_algorithm_with_custom_name_and_vecnormalize(tiny_dataset: Path, tmp_path: Path) -> None:
    from sb3_contrib import TQC
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    table = load_table(tiny_dataset)
    env = SolarChainEnv(config=BenchmarkConfig(), table=table)
    model = TQC("MlpPolicy", env, seed=0, device="cpu", policy_kwargs={"net_arch": [8]})
    model.save(tmp_path / "tqc.zip")
    venv = VecNormalize(DummyVecEnv([lambda: SolarChainEnv(config=BenchmarkConfig(), table=table)]))
    venv.reset()
    for _ in range(30):
        venv.step(np.array([[0.5, 0.5, 0.5]], dtype=np.float32))
    venv.save(tmp_path / "vecnormalize.pkl")
    out = tmp_path / "run"
    result = _evaluate(
        [
            "--data",
            str(tiny_dataset),
            "--policies",
            f"my-tqc=sb3:tqc:{tmp_path / 'tqc.zip'},plain=sb3:TQC:{tmp_path / 'tqc.zip'}",
            "--vecnormalize",
            f"my-tqc={tmp_path / 'vecnormalize.pkl'}",
            "--out",
            str(out),
        ]
    )
    assert result.exit_code == 0, result.output
    actions = pd.read_csv(out / "actions.csv")
    first = actions.groupby("policy").first()
    obs, _ = env.reset(seed=SEED)
    stats = VecNormalize.load(tmp_path / "vecnormalize.pkl", DummyVecEnv([lambda: env]))
    expected = env.codec.decode(model.predict(stats.normalize_obs(obs), deterministic=True)[0])
    plain = env.codec.decode(model.predict(obs, deterministic=True)[0])
    assert first.loc["my-tqc", "reward_ratio"] == pytest.approx(expected[0], abs=1e-6)
    assert first.loc["plain", "reward_ratio"] == pytest.approx(plain[0], abs=1e-6)
    assert expected[0] != pytest.approx(plain[0], abs=1e-6)  # the statistics changed what the model saw


def test_installed_plugins_are_found_by_name(tiny_dataset: Path, agent_file: Path, tmp_path: Path, monkeypatch) -> None:
    site = tmp_path / "site"
    dist = site / "my_plugin-1.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: my-plugin\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[solarchain_eval.agents]\nconstant-plugin = my_agent:make\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(agent_file.parent))
    monkeypatch.delitem(sys.modules, "my_agent", raising=False)
    out = tmp_path / "run"
    result = _evaluate(["--data", str(tiny_dataset), "--policies", "constant-plugin", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert set(pd.read_csv(out / "metrics.csv")["policy"]) == {"constant-plugin"}


def test_a_plugin_agents_record_holds_its_module_files_sha256_and_version(agent_file: Path, tmp_path, monkeypatch):
    site = tmp_path / "site"
    dist = site / "my_plugin-1.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: my-plugin\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[solarchain_eval.agents]\nconstant-plugin = my_agent:make\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(agent_file.parent))
    monkeypatch.delitem(sys.modules, "my_agent", raising=False)  # imported from another test's folder
    record = agent_identity("constant-plugin", "constant-plugin", {}, {})
    assert record["sha256"] == {"source": hashlib.sha256(agent_file.read_bytes()).hexdigest()}
    assert record["plugin"] == {"entry_point": "my_agent:make", "version": "1.0"}
    agent_file.write_text(agent_file.read_text() + "\n# changed\n")  # a grid resumed now redoes its units
    assert agent_identity("constant-plugin", "constant-plugin", {}, {})["sha256"] != record["sha256"]
