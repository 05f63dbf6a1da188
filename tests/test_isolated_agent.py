"""The isolated door (``--isolate``, ``isolate=True``) and the access labels, tested as the attack.

An agent in the evaluating process can find the environment through the interpreter (``gc``, a
stack walk) and rewrite the episode: the in-process door's limit. Behind the isolated door the
same code finds nothing, and its rows are an honest agent's.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from isolated_agents import (
    BadAt,
    Counter,
    Echo,
    FailingObserve,
    Honest,
    RaisesAtStep,
    ReturnsEvil,
    constant,
    static_action,
)
from solarchain_eval.agents.adapters import AgentError
from solarchain_eval.agents.base import access_label
from solarchain_eval.agents.isolated import IsolatedAgent, IsolatedAgentError
from solarchain_eval.agents.specs import AgentSpecError
from solarchain_eval.agents.wire import WireError, decode, encode, frameable, pack_array, unpack_array
from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation
from solarchain_eval.evaluation.verify import VerifyOptions, verify_run
from solarchain_eval.market.baselines import make_baseline

SEED = 20260511
RECORDS = ("metrics.csv", "actions.csv", "city_hour_policy.csv", "summary.json")

#: The attack of issue 32: find the environment from act() and zero the unsafe supply and the price noise.
CHEATER = textwrap.dedent(
    """
    import gc
    import sys

    import numpy as np


    def find_envs():
        # the env, and its hourly table (720 hours ahead), wherever they are in this process's memory
        found = [o for o in gc.get_objects() if type(o).__name__ in ("SolarChainEnv", "HourlyTable")]
        frame = sys._getframe()
        while frame is not None:  # the stack walk: the runner's frame holds the env as a local
            found += [v for v in frame.f_locals.values() if type(v).__name__ == "SolarChainEnv"]
            frame = frame.f_back
        return found


    class Cheater:
        name = "cheater"

        def __init__(self, action=(0.5, 0.5, 0.5), report=None):
            self.action = np.asarray(action, dtype=np.float32)
            self.report = report
            self.first = True

        def begin_episode(self, **context):
            self.first = True

        def act(self, observation):
            if self.first:  # once per episode (gc.get_objects() is slow), after the env's reset
                self.first = False
                envs = find_envs()
                for env in (o for o in envs if type(o).__name__ == "SolarChainEnv"):
                    env._unsafe = [0.0] * len(env._unsafe)
                    env._noise = [0.0] * len(env._noise)
                if self.report:
                    with open(self.report, "a") as out:
                        out.write(f"{len(envs)}\\n")
            return self.action
    """
)


def _run(tmp_path: Path, name: str, policies: list, data: Path, **options) -> Path:
    out = tmp_path / name
    _EVALUATIONS[name] = solarchain_eval.evaluate(
        policies, data=data, seeds=[SEED, SEED + 1], episodes=2, out=out, **options
    )
    return out


_EVALUATIONS: dict[str, solarchain_eval.Evaluation] = {}


def _frame(run: Path) -> pd.DataFrame:
    return pd.read_csv(run / "metrics.csv").drop(columns=["policy"])


def _access_of(run: Path) -> dict:
    return json.loads((run / "run_metadata.json").read_text())["policy_access"]


def test_the_attack_rewrites_the_episode_in_process_and_finds_nothing_isolated(
    tiny_dataset: Path, tmp_path: Path
) -> None:
    agent_file = tmp_path / "cheater.py"
    agent_file.write_text(CHEATER)
    spec = f"{agent_file}:Cheater"
    args = {None: {"action": static_action(), "report": str(tmp_path / "found.txt")}}
    honest = _run(tmp_path, "honest", ["static"], tiny_dataset)

    # In-process: the agent reaches the env and rewrites the episode (the in-process door's limit).
    cheated = _run(tmp_path, "in-process", [spec], tiny_dataset, agent_args=args)
    found = [int(n) for n in (tmp_path / "found.txt").read_text().split()]
    assert found and min(found) >= 1
    assert _frame(cheated)["cumulative_reward"].mean() > _frame(honest)["cumulative_reward"].mean() + 0.5
    assert _access_of(cheated) == {"cheater": "in-process"}

    # Isolated: the same code finds no env, and its rows are the honest baseline's, bit for bit.
    (tmp_path / "found.txt").unlink()
    isolated = _run(tmp_path, "isolated", [spec], tiny_dataset, agent_args=args, isolate=True)
    found = [int(n) for n in (tmp_path / "found.txt").read_text().split()]
    assert len(found) == 2 * 2 and set(found) == {0}  # one search per episode
    pd.testing.assert_frame_equal(_frame(isolated), _frame(honest), check_exact=True)
    assert _access_of(isolated) == {"cheater": "isolated"}

    # verify re-runs a submitted agent isolated: the cheated run no longer checks out.
    check = verify_run(cheated, VerifyOptions(episodes=1, agents=(spec,), agent_args=args))
    assert [p.status for p in check.policies] == ["differs"]
    assert not check.ok


def test_isolated_rows_equal_in_process_rows_bit_for_bit(tiny_dataset: Path, tmp_path: Path) -> None:
    in_process = _run(tmp_path, "in-process", [Honest(), constant, "static"], tiny_dataset)
    isolated = _run(tmp_path, "isolated", [Honest(), constant, "static"], tiny_dataset, isolate=True)
    for name in RECORDS:
        assert (isolated / name).read_bytes() == (in_process / name).read_bytes(), name
    assert _access_of(in_process) == {"honest": "in-process", "constant": "in-process", "static": "in-process"}
    assert _access_of(isolated) == {"honest": "isolated", "constant": "isolated", "static": "in-process"}

    # what end_episode() returned comes back with its types and bits
    # (the door namespaces it: {"agent_columns": {"agent_<key>": value}})
    def typed(evaluation: str) -> list:
        columns = [e.extras["agent_columns"] for e in _EVALUATIONS[evaluation].episodes if "agent_columns" in e.extras]
        return [(c, {k: type(v) for k, v in c.items()}) for c in columns]

    extras = typed("in-process")
    assert extras[0][0]["agent_steps_seen"] == 24
    assert typed("isolated") == extras


def test_a_copy_of_an_isolated_agent_goes_on_from_its_state_in_a_process_of_its_own() -> None:
    import copy

    original = IsolatedAgent.from_object(Counter())
    observation = np.zeros(12, np.float32)
    try:
        assert [original.act(observation)[0] for _ in range(3)] == [0.01, 0.02, 0.03]
        twin = copy.deepcopy(original)
        try:
            assert twin.act(observation)[0] == 0.04 and twin.act(observation)[0] == 0.05
            assert original.act(observation)[0] == 0.04  # the original's state did not move
        finally:
            twin.close()
    finally:
        original.close()


def test_episodes_in_flight_copy_an_isolated_agent_faithfully(tiny_dataset: Path, tmp_path: Path) -> None:
    """A stateful agent gets a private copy per run seed (episodes in flight): a process of its own each."""
    spec = EvaluationSpec(
        policies=[Honest()], run_seeds=(SEED, SEED + 1), episodes=2, data_dir=tiny_dataset, concurrency=2
    )
    in_process = run_evaluation(spec, tmp_path / "in-process")
    spec.isolate = True
    isolated = run_evaluation(spec, tmp_path / "isolated")
    for name in RECORDS:
        assert (tmp_path / "isolated" / name).read_bytes() == (tmp_path / "in-process" / name).read_bytes(), name
    assert isolated.access == {"honest": "isolated"} and in_process.access == {"honest": "in-process"}


def test_the_command_line_runs_a_file_agent_isolated(tiny_dataset: Path, tmp_path: Path) -> None:
    agent_file = tmp_path / "mine.py"
    agent_file.write_text("def mine(observation):\n    return [0.4, 0.6, 0.1]\n")
    out = tmp_path / "run"
    command = ["evaluate", "--data", str(tiny_dataset), "--seeds", str(SEED), "--episodes", "1", "--out", str(out)]
    result = CliRunner().invoke(app, [*command, "--policies", f"{agent_file}:mine,static", "--isolate"])
    assert result.exit_code == 0, result.output
    assert _access_of(out) == {"mine": "isolated", "static": "in-process"}
    from solarchain_eval.report.loading import load_report_data
    from solarchain_eval.report.paper.provenance import run_records

    # the report's run metadata shows each row's access
    assert run_records(load_report_data(out))[0]["policy_access"] == {"mine": "isolated", "static": "in-process"}


def test_an_agent_that_cannot_be_pickled_is_refused_in_one_line(tiny_dataset: Path) -> None:
    with pytest.raises(AgentSpecError, match=r"^agent 'anon': an isolated agent is copied .* pickled") as caught:
        solarchain_eval.evaluate(
            lambda obs: [0.5, 0.5, 0.5], name="anon", data=tiny_dataset, seeds=[SEED], episodes=1, isolate=True
        )
    assert "\n" not in str(caught.value)


def _isolated(agent) -> object:
    return IsolatedAgent.from_object(agent)


def test_failures_in_the_agents_process_are_one_line_errors_naming_the_position() -> None:
    shell = _isolated(RaisesAtStep(2))
    try:
        shell.begin_run(SEED)
        shell.begin_episode(episode=0, run_seed=SEED, episode_seed=SEED, start_hour=5)
        assert list(shell.act(np.zeros(12, np.float32))) == [0.5, 0.5, 0.5]
        with pytest.raises(IsolatedAgentError) as caught:
            shell.act(np.zeros(12, np.float32))
        assert str(caught.value) == (
            f"agent 'raises' (isolated): act() raised ValueError: no market for me (run seed {SEED}, episode 0, step 2)"
        )
    finally:
        shell.close()
    shell = _isolated(FailingObserve(99))
    try:
        shell.act(np.zeros(12, np.float32))
        shell.observe({"reward": 1.0})  # sent without waiting: its error comes with the next act
        with pytest.raises(IsolatedAgentError, match=r"observe\(\) raised KeyError: 'reward'"):
            shell.act(np.zeros(12, np.float32))
    finally:
        shell.close()


def test_a_wrong_action_reads_as_in_process_and_a_dead_process_is_named() -> None:
    shell = _isolated(RaisesAtStep(1, "shape"))
    with pytest.raises(AgentError) as caught:
        shell.act(np.zeros(12, np.float32))
    shell.close()
    assert (
        str(caught.value)
        == "agent 'raises': act() returned an action of shape (2,); a continuous action has shape (3,)"
    )
    shell = _isolated(RaisesAtStep(1, "object"))
    # the door in the agent's process refuses it as the in-process door does, before the wire sees it
    with pytest.raises(
        AgentError, match=r"act\(\) returned .*; a continuous action is three numbers in \[0, 1\], not object"
    ):
        shell.act(np.zeros(12, np.float32))
    shell.close()
    shell = _isolated(RaisesAtStep(1, "exit"))
    with pytest.raises(IsolatedAgentError, match=r"act\(\) ended its process \(exit code 3\) before answering"):
        shell.act(np.zeros(12, np.float32))
    shell.close()


@pytest.mark.parametrize(
    "bad",
    [
        np.float32([np.nan, 0.5, 0.5]),
        np.float64([0.5, 1.5, 0.5]),
        np.float32([0.5, 0.5]),
        np.int64([0, 1, 2]),
        np.zeros((3, 1), np.float32),
        ["0.5", "0.5", "0.5"],
    ],
)
def test_an_invalid_action_reads_the_same_through_both_doors(tiny_dataset: Path, bad) -> None:
    # a numeric array crosses as a frame and the evaluating process's door checks it; the rest is
    # checked in the agent's process: either way the line is the in-process door's, word for word
    messages = []
    for isolate in (False, True):
        with pytest.raises(AgentError) as caught:
            solarchain_eval.evaluate(BadAt(bad), data=tiny_dataset, seeds=[SEED], episodes=2, isolate=isolate)
        messages.append(str(caught.value))
    assert messages[0] == messages[1], messages
    assert messages[0].startswith("agent 'bad': act() returned") and messages[0].endswith(
        "episode 1, step 2)"
    )  # steps count from 0


def test_a_spec_that_cannot_be_built_reads_as_in_process(tmp_path: Path) -> None:
    from solarchain_eval.agents.registry import make_agent
    from solarchain_eval.agents.specs import parse_agent_spec

    (tmp_path / "broken.py").write_text("raise ImportError('no such thing')\n")
    spec = parse_agent_spec(f"{tmp_path / 'broken.py'}:Agent", ())
    with pytest.raises(AgentSpecError) as in_process:
        make_agent(spec, BenchmarkConfig())
    with pytest.raises(AgentSpecError) as isolated:
        IsolatedAgent.from_spec(spec, BenchmarkConfig())
    assert str(isolated.value) == str(in_process.value)
    (tmp_path / "exits.py").write_text("import sys\nsys.exit(0)\n")
    exits = parse_agent_spec(f"{tmp_path / 'exits.py'}:Agent", ())
    with pytest.raises(AgentSpecError) as in_process:  # sys.exit at import is the door's one line, not an exit
        make_agent(exits, BenchmarkConfig())
    with pytest.raises(AgentSpecError, match=r"raised SystemExit\(0\): the agent called sys.exit$") as isolated:
        IsolatedAgent.from_spec(exits, BenchmarkConfig())
    assert str(isolated.value) == str(in_process.value)


def test_what_the_agent_returns_is_data_never_a_pickle(tmp_path: Path) -> None:
    marker = tmp_path / "ran-in-the-evaluator"
    shell = _isolated(ReturnsEvil(str(marker)))
    # refused by the door in the agent's own process, as in-process; nothing crosses as a pickle
    with pytest.raises(AgentError, match=r"end_episode\(\) 'payload' is Evil .*; values are finite numbers"):
        shell.end_episode()
    shell.close()
    assert not marker.exists()


@pytest.mark.parametrize(
    "value",
    [
        None,
        [1, 2.5, float("nan"), float("inf"), True, "x"],
        (np.float32(0.1), np.int64(7), np.bool_(True)),
        {"a": np.arange(6, dtype=">i2").reshape(2, 3), "b": np.float32([0.1, 0.2, 0.3]), "c": b"\x00\xff"},
        np.array(3.5),
    ],
)
def test_the_wire_keeps_types_and_bits(value) -> None:
    back = decode(encode(value))
    assert type(back) is type(value)
    assert repr(back) == repr(value) or (isinstance(value, np.ndarray) and back.dtype == value.dtype)
    if isinstance(value, dict):
        for key, item in value.items():
            assert type(back[key]) is type(item)
            if isinstance(item, np.ndarray):
                assert back[key].dtype == item.dtype and back[key].tobytes() == item.tobytes()
                assert back[key].shape == item.shape and back[key].flags.writeable


@pytest.mark.parametrize(
    "answer",
    [
        b'{"a":["|O8",[1],"AAAAAAAAAAA="]}',  # an object array would hold references
        b'{"a":["<f8",[2],"AAAAAAAAAAA="]}',  # fewer bytes than the shape says
        b'{"p":"gASVAAAAAAAAAAA="}',  # an unknown tag (a pickle) is not read
        b"[" * 100000 + b"]" * 100000,
        b"\x80\x04K\x01.",  # a raw pickle
    ],
)
def test_the_wire_refuses_anything_but_data(answer: bytes) -> None:
    with pytest.raises(WireError):
        decode(answer)


@pytest.mark.parametrize(
    "array",
    [
        np.float32([0.1, np.nan, -np.inf]),
        np.arange(6, dtype=">i2").reshape(2, 3),
        np.array(3.5),
        np.zeros((0, 4), dtype=np.uint8),
        np.array([True, False]),
        np.arange(12, dtype=np.float64).reshape(3, 4).T,  # not contiguous: the values travel, in C order
    ],
)
def test_an_array_frame_keeps_dtype_shape_and_bits(array: np.ndarray) -> None:
    assert frameable(array)
    label, back = unpack_array(pack_array("act", array))
    assert label == "act" and back.dtype == array.dtype and back.shape == array.shape
    assert back.tobytes() == np.ascontiguousarray(array).tobytes() and back.flags.writeable


@pytest.mark.parametrize(
    "frame",
    [
        b"\x00act\x00|O8\x001\x00" + bytes(8),  # an object array would hold references
        b"\x00act\x00<U1\x001\x00" + bytes(4),  # strings are not a numeric dtype
        b"\x00act\x00<f4\x003\x00" + bytes(8),  # fewer bytes than the shape says
        b"\x00act\x00<f4\x00-3\x00",  # not a shape
        b"\x00act\x00<f4\x0099999999999999\x00",  # a shape too large to be real
        b"\x00act\x00<f4",  # a header cut short
        b"\x00\xff\x00<f4\x001\x00" + bytes(4),  # a label that is not ASCII
    ],
)
def test_an_array_frame_refuses_anything_but_a_numeric_array(frame: bytes) -> None:
    with pytest.raises(WireError):
        unpack_array(frame)
    with pytest.raises(WireError):  # nor is a frame read where JSON is expected
        decode(frame)
    assert not frameable(np.array(["x"])) and not frameable(np.array([object()])) and not frameable([1.0])


def test_observations_and_actions_cross_as_frames_with_their_exact_bits() -> None:
    shell = _isolated(Echo())
    shell.begin_run(SEED)
    shell.begin_episode(episode=0, run_seed=SEED, episode_seed=1, start_hour=0)
    for dtype in (np.float32, np.float64, ">f8"):
        observation = np.array([0.1, 1 / 3, 0.7, 5.0], dtype=dtype)
        action = shell.act(observation)
        assert type(action) is np.ndarray and action.dtype == observation.dtype
        assert action.tobytes() == observation[:3].tobytes()
    shell.close()


def test_labels_the_benchmarks_own_agents_and_refuses_a_users_claim() -> None:
    # (older runs' "public" label reads as "in-process": tests/test_run_metadata.py)
    assert access_label(make_baseline("static", BenchmarkConfig().market)) == "in-process"

    class Claims:
        isolated = True  # a user's class cannot claim the label

        def act(self, observation):
            return [0.5, 0.5, 0.5]

    assert access_label(Claims()) == "in-process"


def test_bench_agent_times_the_isolated_door_beside_the_python_agent(tiny_dataset: Path) -> None:
    from solarchain_eval.perf.agent_bench import measure_agent_overhead

    result = measure_agent_overhead(tiny_dataset, seeds=1, episodes=2, repeats=2)
    assert result.steps == 2 * 24
    assert len(result.isolated_s) == len(result.isolated_cpu_s) == len(result.python_s) == 2
    assert result.isolated_start_s > 0 and min(result.isolated_s) > 0
    expected = 1000 * (np.median(result.isolated_s) - np.median(result.python_s)) / result.steps
    assert result.isolated_overhead_ms_per_step == pytest.approx(expected)
    assert result.isolated_over_python == pytest.approx(np.median(result.isolated_s) / np.median(result.python_s))
