"""What evaluating your own agent costs (``solarchain-eval bench-agent``).

Two comparisons on the same episodes, each evaluation written to a temporary run directory
by :func:`~solarchain_eval.evaluation.runner.run_evaluation`:

- the Static baseline against a plain Python agent object that takes the same action (the
  runner's cost for a policy it did not build);
- that Python agent against an :class:`~solarchain_eval.agents.http_agent.HttpAgent` asking
  the example agent server (``examples/http_agent_server.py``, started with the same constant
  action) or a server already running: the difference per step is the HTTP round trip;
- that Python agent against the same agent behind the isolated door
  (:class:`~solarchain_eval.agents.isolated.IsolatedAgent`, one process started once and timed
  apart): the difference per step is the pipe's round trip.

The measurements alternate within each repeat so that a slow spell of a shared machine
affects all of them; medians and bests are reported.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from contextlib import closing, contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..agents.base import Policy
from ..agents.http_agent import HttpAgent
from ..agents.isolated import IsolatedAgent
from ..config import BenchmarkConfig, MarketConfig
from ..evaluation.run_spec import EvaluationSpec
from ..evaluation.runner import run_evaluation
from ..protocol import PAPER_EPISODES, PAPER_SEEDS
from ..tasks.registry import get_task

#: The example agent server of a source checkout (it is not part of the installed package).
EXAMPLE_SERVER = Path(__file__).resolve().parents[3] / "examples" / "http_agent_server.py"
_SERVER_START_S = 30.0


@dataclass
class ConstantAgent:
    """A user's agent as a plain Python object: the same action every hour."""

    action: np.ndarray
    name: str = "python-agent"
    action_mode: str = "continuous"

    def begin_run(self, run_seed: int) -> None:
        return None

    def act(self, observation: np.ndarray) -> np.ndarray:
        return self.action


@dataclass(frozen=True)
class AgentBench:
    """Seconds per evaluation of each policy (one sample per repeat) over ``steps`` env steps.

    ``*_s`` are wall times; ``python_cpu_s``, ``http_cpu_s`` and ``isolated_cpu_s`` the CPU time of
    this process (its share of the round trip, which a busy machine inflates less than the wall
    time: the server's or the agent process's own time is not in it).
    """

    steps: int
    static_s: tuple[float, ...]
    python_s: tuple[float, ...]
    http_s: tuple[float, ...]
    python_cpu_s: tuple[float, ...]
    http_cpu_s: tuple[float, ...]
    url: str
    #: The Python agent behind the isolated door (its process already started), and that start's wall time.
    isolated_s: tuple[float, ...] = ()
    isolated_cpu_s: tuple[float, ...] = ()
    isolated_start_s: float = 0.0

    @property
    def python_over_static(self) -> float:
        """Median Python-agent time over median Static time."""
        return statistics.median(self.python_s) / statistics.median(self.static_s)

    @property
    def http_overhead_ms_per_step(self) -> float:
        """(median HTTP time - median Python time) per env step, milliseconds."""
        return 1000.0 * (statistics.median(self.http_s) - statistics.median(self.python_s)) / self.steps

    @property
    def isolated_over_python(self) -> float:
        """Median isolated-agent time over median Python-agent time."""
        return statistics.median(self.isolated_s) / statistics.median(self.python_s)

    @property
    def isolated_overhead_ms_per_step(self) -> float:
        """(median isolated time - median Python time) per env step, milliseconds."""
        return 1000.0 * (statistics.median(self.isolated_s) - statistics.median(self.python_s)) / self.steps

    @property
    def isolated_cpu_ms_per_step(self) -> float:
        """(median isolated CPU time - median Python CPU time) of this process per env step, milliseconds."""
        return 1000.0 * (statistics.median(self.isolated_cpu_s) - statistics.median(self.python_cpu_s)) / self.steps

    @property
    def http_client_cpu_ms_per_step(self) -> float:
        """(median HTTP CPU time - median Python CPU time) of this process per env step, milliseconds."""
        return 1000.0 * (statistics.median(self.http_cpu_s) - statistics.median(self.python_cpu_s)) / self.steps


def static_action(market: MarketConfig | None = None) -> np.ndarray:
    """The Static baseline's normalised action (float32, as it acts), from the solar market's baselines."""
    config = BenchmarkConfig() if market is None else BenchmarkConfig(market=market)
    return np.array(get_task().baselines()["static"](config).act(np.zeros(0)), dtype=np.float32)


@contextmanager
def example_server(action: Sequence[float], script: Path = EXAMPLE_SERVER) -> Iterator[str]:
    """Run the example agent server on a free port, answering ``action``; yields its URL."""
    if not script.is_file():
        raise FileNotFoundError(
            f"the example agent server is not at {script} (it ships with the source repository); "
            "start an agent server and pass its URL instead"
        )
    constant = ",".join(repr(float(v)) for v in action)  # repr: the float32 values exactly
    # stderr goes to a file, not a pipe nobody reads, which could fill up and stall the server.
    with tempfile.TemporaryFile("w+") as errors:
        process = subprocess.Popen(
            [sys.executable, str(script), "--port", "0", "--constant", constant],
            stdout=subprocess.PIPE,
            stderr=errors,
            text=True,
        )
        try:
            line = process.stdout.readline() if process.stdout is not None else ""
            if not line.strip():
                process.wait(timeout=_SERVER_START_S)
                errors.seek(0)
                raise RuntimeError(f"the example agent server did not start: {' '.join(errors.read().split())[-300:]}")
            yield line.split()[-1]
        finally:
            process.terminate()
            process.wait(timeout=_SERVER_START_S)
            if process.stdout is not None:
                process.stdout.close()


def evaluation_seconds(
    policy: Policy | str, data_dir: Path | None, run_seeds: Sequence[int], episodes: int
) -> tuple[float, float, int]:
    """Wall and CPU seconds of one evaluation of ``policy`` into a temporary run directory, and its env steps."""
    spec = EvaluationSpec(policies=[policy], run_seeds=tuple(run_seeds), episodes=episodes, data_dir=data_dir)
    with tempfile.TemporaryDirectory() as tmp:
        start, start_cpu = time.perf_counter(), time.process_time()
        outcome = run_evaluation(spec, Path(tmp) / "run", command=["bench-agent"])
        wall_s, cpu_s = time.perf_counter() - start, time.process_time() - start_cpu
        return wall_s, cpu_s, sum(r.n_steps for r in outcome.results)


def measure_agent_overhead(
    data_dir: Path | None = None,
    *,
    seeds: int = len(PAPER_SEEDS),
    episodes: int = PAPER_EPISODES,
    repeats: int = 3,
    url: str | None = None,
) -> AgentBench:
    """Time Static, the constant Python agent, the HTTP agent and the isolated agent on the same episodes.

    Parameters
    ----------
    data_dir : Path, optional
        Dataset (default: the embedded default dataset).
    seeds, episodes : int
        The first ``seeds`` of the paper's run seeds, ``episodes`` episodes each.
    repeats : int
        Samples per policy (after one untimed evaluation of each, which loads the data).
    url : str, optional
        An agent server already running; default: start the example server with Static's action.
    """
    if not 1 <= seeds <= len(PAPER_SEEDS):
        raise ValueError(f"seeds must be 1..{len(PAPER_SEEDS)}, not {seeds}")
    run_seeds = PAPER_SEEDS[:seeds]
    action = static_action()
    python_agent = ConstantAgent(action)
    server = example_server(action) if url is None else nullcontext(url)
    start = time.perf_counter()
    isolated_agent = IsolatedAgent.from_object(ConstantAgent(action, name="isolated-agent"))
    isolated_start_s = time.perf_counter() - start
    with closing(isolated_agent), server as agent_url, HttpAgent("http-agent", agent_url) as http_agent:
        policies: dict[str, Policy | str] = {
            "static": "static",
            "python": python_agent,
            "http": http_agent,
            "isolated": isolated_agent,
        }
        for policy in policies.values():
            evaluation_seconds(policy, data_dir, run_seeds[:1], 1)
        samples: dict[str, list[float]] = {key: [] for key in policies}
        cpu: dict[str, list[float]] = {key: [] for key in policies}
        steps: set[int] = set()
        for _ in range(repeats):
            for key, policy in policies.items():
                wall_s, cpu_s, n_steps = evaluation_seconds(policy, data_dir, run_seeds, episodes)
                samples[key].append(wall_s)
                cpu[key].append(cpu_s)
                steps.add(n_steps)
    if len(steps) != 1:  # the same action on the same episodes: the same steps
        raise RuntimeError(f"the evaluations played different numbers of steps: {sorted(steps)}")
    return AgentBench(
        steps=steps.pop(),
        static_s=tuple(samples["static"]),
        python_s=tuple(samples["python"]),
        http_s=tuple(samples["http"]),
        python_cpu_s=tuple(cpu["python"]),
        http_cpu_s=tuple(cpu["http"]),
        url=http_agent.shown_url,
        isolated_s=tuple(samples["isolated"]),
        isolated_cpu_s=tuple(cpu["isolated"]),
        isolated_start_s=isolated_start_s,
    )
