"""``solarchain-eval verify``: checksums, protocol, and episodes re-run bit for bit.

One tiny run (1 run seed × 3 episodes of static, random, myopic and a stateful user agent from a
file) is written once; each test verifies a copy, untouched or tampered with.
"""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from fake_openai import FakeOpenAI
from solarchain_eval.cli import app
from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation
from solarchain_eval.evaluation.verify import VerifyOptions, choose_episodes, default_seed, replay_plan, verify_run
from solarchain_eval.evaluation.verify_checks import same_cell

RUN_SEED = 5
# Not stateless: its action depends on the steps taken since begin_run, across a run's episodes.
AGENT_SOURCE = """
import numpy as np


class MyAgent:
    name = "mine"

    def __init__(self, scale=1.0):
        self.scale = float(scale)
        self._t = 0

    def begin_run(self, run_seed):
        self._t = 0

    def act(self, observation):
        self._t += 1
        k = self._t % 7
        return np.array([0.1 + 0.1 * (k % 3), 0.5, 0.02 * k * self.scale], dtype=np.float32)


class CarryAgent(MyAgent):
    name = "carry"

    def begin_run(self, run_seed):
        pass  # carries its state from one run seed to the next too
"""


def invoke(*args: str):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def agent_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("agent") / "my_agent.py"
    path.write_text(AGENT_SOURCE)
    return path


@pytest.fixture(scope="module")
def agent_spec(agent_file) -> str:
    return f"mine={agent_file}:MyAgent"


@pytest.fixture(scope="module")
def pristine(tiny_dataset, agent_spec, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "run"
    result = invoke(
        "evaluate", "--data", tiny_dataset, "--policies", f"static,random,myopic,{agent_spec}",
        "--seeds", RUN_SEED, "--episodes", 3, "--out", out,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture
def run(pristine, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(pristine, copy)
    return copy


def metadata(run: Path) -> dict:
    return json.loads((run / "run_metadata.json").read_text())


def write_metadata(run: Path, meta: dict) -> None:
    (run / "run_metadata.json").write_text(json.dumps(meta))


def forge_cell(run: Path, policy: str, episode: int, column: str, value: str) -> str:
    """Replace one metrics.csv cell and re-vouch for the file; returns the cell's old text."""
    path = run / "metrics.csv"
    rows = list(csv.reader(io.StringIO(path.read_text())))
    header = rows[0]
    (row,) = [r for r in rows[1:] if r[header.index("policy")] == policy and r[header.index("episode")] == str(episode)]
    old, row[header.index(column)] = row[header.index(column)], value
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    path.write_text(buffer.getvalue())
    meta = metadata(run)
    meta["files"]["metrics.csv"] = sha256_file(path)
    write_metadata(run, meta)
    return old


def lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.strip()]


def test_untouched_run_verifies_every_policy(run, agent_spec):
    result = invoke("verify", run, "--agent", agent_spec)
    assert result.exit_code == 0, result.output
    protocol_id = metadata(run)["protocol_id"]
    assert lines(result.output) == [
        "static: verified (3 episodes)",
        "random: verified (3 episodes)",
        "myopic: verified (3 episodes)",
        "mine: verified (3 episodes)",
        f"checksums match (4 files); protocol {protocol_id}",
    ]


def test_forged_value_with_recomputed_checksum_is_caught_by_the_rerun(run, agent_spec):
    old = forge_cell(run, "random", 1, "cumulative_reward", "123.456")
    result = invoke("verify", run, "--agent", agent_spec)
    assert result.exit_code == 1, result.output
    out = lines(result.output)
    assert (
        out[1]
        == f"random: differs: episode 1 of run seed {RUN_SEED}, metric cumulative_reward: recorded 123.456, re-run {old}"
    )
    assert out[0] == "static: verified (3 episodes)" and out[-1].startswith("checksums match (4 files)")


def test_changed_missing_and_extra_files_fail_the_checksum_step(run, agent_spec):
    with open(run / "actions.csv", "a") as handle:
        handle.write("\n")
    (run / "summary.json").unlink()
    (run / "notes.csv").write_text("x\n")
    result = invoke("verify", run, "--agent", agent_spec)
    assert result.exit_code == 1, result.output
    out = lines(result.output)
    assert out[:4] == [f"{p}: verified (3 episodes)" for p in ("static", "random", "myopic", "mine")]
    assert out[4:7] == [
        f"checksum: {run / 'actions.csv'} does not match the sha256 in run_metadata.json (changed, or from another run)",
        f"checksum: {run / 'summary.json'} is listed in run_metadata.json but missing",
        f"checksum: {run / 'notes.csv'} is not vouched for by run_metadata.json (left over from another run)",
    ]
    assert out[-1] == f"checksums FAIL (3 problem(s)); protocol {metadata(run)['protocol_id']}"


def test_the_report_folder_is_not_an_extra_file_but_another_folder_is(run, agent_spec):
    report = invoke("report", run, "--format", "md")  # writes RUN/report, derived from the vouched files
    assert report.exit_code == 0, report.output
    assert invoke("verify", run, "--agent", agent_spec).exit_code == 0
    (run / "extra").mkdir()
    result = invoke("verify", run, "--agent", agent_spec)
    assert result.exit_code == 1 and f"{run / 'extra'} is not a file" in result.output


def test_user_agent_needs_its_spec_and_agent_args(run, agent_spec):
    without = invoke("verify", run)
    assert without.exit_code == 0, without.output
    assert f"mine: cannot rebuild (a user agent ({agent_spec}); pass its spec with --agent to rebuild it)" in lines(
        without.output
    )
    # The agent's options reach it: another scale is another agent, caught on its first episode.
    other = invoke("verify", run, "--agent", agent_spec, "--agent-arg", "mine.scale=2")
    assert other.exit_code == 1
    assert f"mine: differs: episode 0 of run seed {RUN_SEED}, metric cumulative_reward" in other.output


@pytest.mark.parametrize("policy", ["random", "mine"])
def test_stateful_agents_replay_the_earlier_episodes_in_order(run, agent_spec, policy):
    # A seed whose single choice is the last episode: the agent's state must come from episodes 0 and 1.
    seed = next(s for s in range(100) if choose_episodes([RUN_SEED], 3, 1, s) == [(RUN_SEED, 2)])
    result = invoke("verify", run, "--agent", agent_spec, "--episodes", 1, "--seed", seed)
    assert result.exit_code == 0, result.output
    assert f"{policy}: verified (1 episode; 2 earlier episode(s) replayed in order)" in lines(result.output)
    assert "static: verified (1 episode)" in lines(result.output)


@pytest.mark.parametrize("concurrency", [1, 2])
def test_state_carried_across_run_seeds_is_replayed_as_the_run_ran(tiny_dataset, agent_file, tmp_path, concurrency):
    # In order (1), one agent runs every run seed; in flight (2), each run seed has its own copy.
    out = tmp_path / "run"
    spec = f"{agent_file}:CarryAgent"
    evaluation = EvaluationSpec([spec], run_seeds=[5, 6], episodes=2, data_dir=tiny_dataset, concurrency=concurrency)
    run_evaluation(evaluation, out)
    seed = next(s for s in range(100) if choose_episodes([5, 6], 2, 1, s) == [(6, 1)])
    (result,) = verify_run(out, VerifyOptions(episodes=1, seed=seed, agents=(spec,))).policies
    assert (result.status, result.episodes, result.replayed) == ("verified", 1, 3 if concurrency == 1 else 1)


def test_replay_plan_runs_what_the_state_needs():
    chosen = [(5, 1), (7, 0)]
    assert replay_plan(chosen, [5, 6, 7], 3, stateless=True, carry_over=True) == [(5, [1]), (7, [0])]
    assert replay_plan(chosen, [5, 6, 7], 3, stateless=False, carry_over=False) == [(5, [0, 1]), (7, [0])]
    assert replay_plan(chosen, [5, 6, 7], 3, stateless=False, carry_over=True) == [
        (5, [0, 1, 2]),
        (6, [0, 1, 2]),
        (7, [0]),
    ]


def test_episode_choice_is_seeded_by_seed_or_the_run_id(run):
    chosen = choose_episodes([1, 2], 3, 4, 7)
    assert chosen == choose_episodes([1, 2], 3, 4, 7) and len(set(chosen)) == 4 and chosen == sorted(chosen)
    assert choose_episodes([1], 3, 5, 0) == [(1, 0), (1, 1), (1, 2)]
    forge_cell(run, "static", 2, "episode_volume", "0.5")
    # Only a choice that includes episode 2 sees the forged cell: the seed decides which.
    for seed in range(4):
        caught = verify_run(run, VerifyOptions(episodes=1, seed=seed)).policies[0].status == "differs"
        assert caught == (choose_episodes([RUN_SEED], 3, 1, seed) == [(RUN_SEED, 2)]), seed
    run_seed_default = default_seed(metadata(run)["run_id"])
    caught = verify_run(run, VerifyOptions(episodes=1)).policies[0].status == "differs"
    assert caught == (choose_episodes([RUN_SEED], 3, 1, run_seed_default) == [(RUN_SEED, 2)])


def test_protocol_fields_must_agree_with_the_metadata(run, agent_spec):
    meta = metadata(run)
    meta["episodes"] = 2  # not checksummed, but the fingerprint says 3
    write_metadata(run, meta)
    result = invoke("verify", run, "--agent", agent_spec)
    assert result.exit_code == 1
    assert "protocol: fingerprint field 'episodes' is 3; this version and the metadata give 2" in lines(result.output)
    assert lines(result.output)[-1].endswith("(inconsistent with the metadata)")


def test_moved_dataset_needs_data_with_the_recorded_csvs(run, agent_spec, tiny_dataset, tmp_path):
    moved = tmp_path / "moved"
    shutil.copytree(tiny_dataset, moved)
    meta = metadata(run)
    meta["dataset"]["data_dir"] = str(tmp_path / "gone")
    write_metadata(run, meta)
    result = invoke("verify", run)
    assert result.exit_code == 0
    assert (
        f"static: cannot rebuild (dataset: {tmp_path / 'gone'} is missing; pass --data DIR with the recorded CSVs)"
        in lines(result.output)
    )
    assert invoke("verify", run, "--data", moved, "--agent", agent_spec).exit_code == 0
    (moved / "p2p_trades.csv").write_text((moved / "p2p_trades.csv").read_text() + "\n")
    refused = invoke("verify", run, "--data", moved)
    assert (
        refused.exit_code == 2 and "--data" in refused.output and "does not have the recorded sha256" in refused.output
    )


def test_usage_errors_exit_2(run, tmp_path, agent_spec):
    assert invoke("verify", tmp_path / "absent").exit_code == 2
    empty = tmp_path / "empty"
    empty.mkdir()
    missing = invoke("verify", empty)
    assert missing.exit_code == 2 and "has no run_metadata.json" in missing.output
    wrong = invoke("verify", run, "--agent", agent_spec.replace("mine=", "yours="))
    assert wrong.exit_code == 2 and "builds agent 'yours'" in wrong.output


def test_same_cell_compares_text_or_exact_float64():
    assert same_cell("1", "1.0") and same_cell("", "nan") and same_cell("rule", "rule")
    assert not same_cell("0.1", "0.10000000000000002") and not same_cell("rule", "llm")


def governed_args(data: Path, out: Path, *extra: str) -> list:
    return [
        "evaluate", "--data", data, "--policies", "static,random", "--seeds", RUN_SEED, "--episodes", 2,
        "--out", out, "--agentic", "planner_auditor", *extra,
    ]  # fmt: skip


def test_governed_rule_run_verifies_and_its_agentic_columns_are_compared(tiny_dataset, tmp_path):
    out = tmp_path / "governed"
    assert invoke(*governed_args(tiny_dataset, out)).exit_code == 0
    result = invoke("verify", out, "--episodes", 2)
    assert result.exit_code == 0, result.output
    assert lines(result.output)[:2] == ["static: verified (2 episodes)", "random: verified (2 episodes)"]
    old = forge_cell(out, "static", 0, "audit_rate", "0.99")
    forged = invoke("verify", out, "--episodes", 2)
    assert forged.exit_code == 1
    assert (
        f"static: differs: episode 0 of run seed {RUN_SEED}, metric audit_rate: recorded 0.99, re-run {old}"
        in forged.output
    )


def test_llm_governed_run_replays_from_its_cache(tiny_dataset, tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    llm = ["--planner", "llm", "--auditor", "llm", "--llm-api", "chat", "--llm-model", "fake-model"]
    monkeypatch.setenv("SOLARCHAIN_LLM_API_KEY", "sk-test-verify")
    out = tmp_path / "llm-run"
    with FakeOpenAI() as server:
        args = governed_args(tiny_dataset, out, *llm, "--llm-base-url", server.base_url, "--llm-cache", cache)
        recorded = invoke(*args, "--llm-cache-mode", "record")
    assert recorded.exit_code == 0, recorded.output
    monkeypatch.delenv("SOLARCHAIN_LLM_API_KEY")
    without = invoke("verify", out)
    assert "static: cannot rebuild (LLM calls; pass --llm-cache)" in lines(without.output)
    replayed = invoke("verify", out, "--llm-cache", cache, "--episodes", 2)
    assert replayed.exit_code == 0, replayed.output
    assert lines(replayed.output)[0] == "static: verified (2 episodes)"
    empty = invoke("verify", out, "--llm-cache", tmp_path / "empty-cache")
    assert "static: cannot rebuild (LLM replay:" in empty.output


def test_paper_root_verifies_each_finished_unit(tiny_dataset, tmp_path):
    root = tmp_path / "grid"
    (root / "units" / "eval").mkdir(parents=True)
    (root / "paper_metadata.json").write_text("{}")
    for policy in ("static", "random"):
        unit = root / "units" / "eval" / f"{policy}-main-{RUN_SEED}"
        unit.mkdir()
        (unit / "unit.json").write_text("{}")
        spec = EvaluationSpec(policies=[policy], run_seeds=[RUN_SEED], episodes=2, data_dir=tiny_dataset)
        run_evaluation(spec, unit, overwrite=True, keep=("unit.json",))
        (unit / "DONE").write_text("{}")
    result = invoke("verify", root, "--episodes", 2)
    assert result.exit_code == 0, result.output
    out = lines(result.output)
    assert out[0] == f"units/eval/random-main-{RUN_SEED}:" and out[1] == "  random: verified (2 episodes)"
    assert out[4] == "  static: verified (2 episodes)" and out[-1] == "combined files: checksums match"
    forge_cell(root / "units" / "eval" / f"static-main-{RUN_SEED}", "static", 1, "final_liquidity", "1.5")
    assert invoke("verify", root, "--episodes", 2).exit_code == 1


@pytest.mark.slow  # trains a tiny PPO model
def test_learned_policy_is_rebuilt_from_the_models_the_keeper_passes(tiny_dataset, tmp_path):
    from solarchain_eval.training.sb3_trainer import TrainSpec, train

    model = train(TrainSpec(algo="ppo", seed=5, timesteps=100, data_dir=tiny_dataset), tmp_path / "ppo").model_path
    out = tmp_path / "run"
    assert invoke("evaluate", "--data", tiny_dataset, "--policies", "ppo", "--models", f"ppo={model}",
                  "--seeds", RUN_SEED, "--episodes", 2, "--out", out).exit_code == 0  # fmt: skip
    result = invoke("verify", out, "--episodes", 2, "--models", f"ppo={model}")
    assert result.exit_code == 0 and lines(result.output)[0] == "ppo: verified (2 episodes)", result.output
    by_dir = invoke("verify", out, "--episodes", 2, "--models", model.parent)
    assert lines(by_dir.output)[0] == "ppo: verified (2 episodes)", by_dir.output
    recorded_only = invoke("verify", out)  # the run records the model's path; verify does not follow it
    assert lines(recorded_only.output)[0].startswith(
        "ppo: cannot rebuild (policy 'ppo' needs a trained model: pass --models"
    )
    model.rename(tmp_path / "elsewhere.zip")
    gone = invoke("verify", out, "--models", f"ppo={model}")
    assert lines(gone.output)[0].startswith("ppo: cannot rebuild (") and str(model) in gone.output


def test_agentic_options_are_rebuilt_from_their_record(tmp_path):
    from solarchain_eval.governance.controls import SchedulerControls
    from solarchain_eval.governance.factory import AgenticOptions, LLMOptions
    from solarchain_eval.llm.client import LLMSettings

    for options in (
        AgenticOptions(),
        AgenticOptions(planner="calibrated-rule", target_audit_rate=0.3, diagnostics=False),
        AgenticOptions(auditor="random", random_audit_rate={"static": 0.25}, random_seed=4,
                       random_audit_counts={("static", 5, 1): 3}, controls=SchedulerControls("hard", 4, 2)),
        AgenticOptions(auditor="oracle", oracle_reward_loss=0.5),
    ):  # fmt: skip
        assert AgenticOptions.from_record(json.loads(json.dumps(options.describe()))) == options
    settings = LLMSettings(api="chat", model="m", base_url="http://127.0.0.1:9/v1", temperature=0.0, seed=3)
    llm = AgenticOptions(planner="llm", llm=LLMOptions(settings, tmp_path, "record"))
    with pytest.raises(Exception, match="llm_cache"):
        AgenticOptions.from_record(llm.describe())
    rebuilt = AgenticOptions.from_record(json.loads(json.dumps(llm.describe())), llm_cache=tmp_path)
    assert rebuilt.llm == LLMOptions(settings, tmp_path, "replay") and rebuilt.planner == "llm"
