"""``solarchain_eval.evaluate``: put any agent through the benchmark's protocol from Python.

::

    import solarchain_eval

    def my_agent(observation):
        return [0.3, 0.7, 0.05]  # reward ratio, liquidity ratio, burn rate, each in [0, 1]

    result = solarchain_eval.evaluate([my_agent, "static", "myopic"], episodes=5)
    print(result.summary)

The agents run through the command line's runner (the same records and run directory), with
the paper's protocol by default: run seeds 20260511-13, 30 episodes each, episode e of seed s
reset with s + e. :func:`evaluate`'s Notes name the command's options it has no parameter for.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from ..agents.names import name_problem
from ..agents.specs import AgentSpecError
from ..governance.factory import AgenticOptions, LLMOptions
from ..protocol import PAPER_EPISODES, PAPER_SEEDS
from ..tasks.registry import DEFAULT_TASK, get_task
from ..tasks.suites import SuiteEntry, SuiteError, get_suite
from .records import metrics_frame, summarize
from .rollout import EpisodeResult
from .run_spec import EvaluationSpec
from .runner import run_evaluation
from .settings import SETTING_MAIN, Setting
from .suite_run import SuiteEvaluation, run_suite


@dataclass
class Evaluation:
    """What :func:`evaluate` returns.

    Attributes
    ----------
    metrics : pandas.DataFrame
        One row per episode (the columns of ``metrics.csv``).
    summary : pandas.DataFrame
        One row per policy and setting: episodes, and mean and sample std of every metric.
    run_dir : Path or None
        The published run directory (``out``), or None when nothing was kept.
    protocol_id : str
        The short id of the run's protocol (equal ids: comparable results).
    protocol : dict
        The protocol fingerprint the id is derived from.
    access : dict
        Policy name -> ``"isolated"``, ``"in-process"`` or ``"privileged"`` (what the agent could reach).
    wall_s : float
        Wall time of the evaluation, in seconds.
    episodes : list of EpisodeResult
        Every episode with its per-step columns.
    """

    metrics: pd.DataFrame
    summary: pd.DataFrame
    run_dir: Path | None
    protocol_id: str
    protocol: dict[str, Any]
    access: dict[str, str]
    wall_s: float
    episodes: list[EpisodeResult] = field(repr=False, default_factory=list)


def summary_frame(summary: list[dict[str, Any]]) -> pd.DataFrame:
    """``summarize``'s entries as a frame: ``policy``, ``setting``, ``episodes``, then
    ``<metric>_mean`` and ``<metric>_std`` for every metric."""
    rows = []
    for entry in summary:
        row: dict[str, Any] = {"policy": entry["policy"], "setting": entry["setting"], "episodes": entry["episodes"]}
        for metric, stats in entry["metrics"].items():
            row[f"{metric}_mean"] = stats["mean"]
            row[f"{metric}_std"] = stats["std"]
        rows.append(row)
    return pd.DataFrame(rows)


def evaluate(
    agent: Any,
    *,
    data: str | Path | None = None,
    seeds: Sequence[int] = PAPER_SEEDS,
    episodes: int = PAPER_EPISODES,
    setting: str | Setting = SETTING_MAIN,
    agentic: AgenticOptions | bool | None = None,
    out: str | Path | None = None,
    name: str | None = None,
    config: Any = None,
    models: dict[str, Path] | None = None,
    agent_args: dict[str | None, dict[str, Any]] | None = None,
    llm: LLMOptions | None = None,
    overwrite: bool = False,
    on_episode: Callable[[EpisodeResult], None] | None = None,
    isolate: bool = False,
    task: str = DEFAULT_TASK,
    suite: str | None = None,
) -> Evaluation | SuiteEvaluation:
    """Evaluate one agent, or several beside built-in ones, over run seeds × episodes.

    Parameters
    ----------
    agent : agent, spec, or a list of them
        An object with ``act(observation)`` (optional hooks: ``begin_run``, ``begin_episode``,
        ``observe``, ``end_episode``, ``close``; attributes ``name``, ``action_mode``,
        ``stateless``), a function ``observation -> action``, a Stable-Baselines3 model, or a
        spec string (``"static"``, ``"pkg.module:MyAgent"``, ``"mine=http://127.0.0.1:8000/act"``,
        see :mod:`solarchain_eval.agents.specs`). A list evaluates each in turn.
    data : path, optional
        Dataset directory (default: the embedded default dataset).
    seeds : sequence of int
        Run seeds (default: the paper's three).
    episodes : int
        Episodes per run seed (default: the paper's 30).
    setting : str or Setting
        ``"main"`` or ``"no_physics"`` (the reward without the physics penalty); the governed
        ``"llm"`` / ``"llm_no_physics"`` run every agent behind the Planner/Auditor layer. Any
        registered setting's name, or a :class:`~solarchain_eval.evaluation.settings.Setting`
        (its config overrides are applied on top of ``config``).
    agentic : AgenticOptions or True, optional
        Run behind the Planner/Auditor layer with these options (True: the rule planner and
        auditor); with ``"main"``/``"no_physics"`` it selects ``"llm"``/``"llm_no_physics"``
        (a setting's governed counterpart: the one declaring a governance contrast with it).
    out : path, optional
        Publish the run directory there (``metrics.csv``, ``actions.csv``, ..., ``run_metadata.json``
        with checksums); by default the run is written to a temporary directory and removed.
    name : str, optional
        The row name of a single agent (default: its ``name``, class or function name). Every
        agent's name follows the command line's rule (letters, digits and ``_ . + -``, at most 64
        characters), differs from the others' in more than case, and is none of the built-in
        names (``static``, ``ppo``, ``llm-agent``, the Planner/Auditor kinds, ...).
    config : BenchmarkConfig or the task's configuration, optional
        The task's configuration (default: the task's own, ``BenchmarkConfig()`` for the solar market).
    models : dict, optional
        Trained models for the built-in learned policies (``{"ppo": path}`` or ``{"*": dir}``).
    agent_args : dict, optional
        Options for agents given as ``"module:Class"`` specs, by agent name (None: all).
    llm : LLMOptions, optional
        The endpoint of the ``"llm-agent"`` baseline.
    overwrite : bool
        Replace an existing ``out``.
    on_episode : callable, optional
        Called with each finished episode (progress).
    isolate : bool
        Run each user agent in a process of its own that receives only the public observation,
        step info and context (:mod:`solarchain_eval.agents.isolated`); an agent object must then
        be picklable. Its rows are labelled ``isolated``.
    task : str
        The market to evaluate in, by name (:func:`~solarchain_eval.tasks.registry.get_task`;
        default ``"solar"``): its environment, dataset, metrics (the ``metrics.csv`` columns) and
        baselines (spec strings naming them).
    suite : str, optional
        Evaluate over every entry of this suite instead (:mod:`solarchain_eval.tasks.suites`, e.g.
        ``"heldout"``; docs/suites.md): one run per entry on the entry's task and dataset, with the
        suite's reference baselines added, under ``out`` (the suite root); ``data`` and ``task`` are
        the suite's and cannot be given.

    Returns
    -------
    Evaluation, or SuiteEvaluation with ``suite``

    Raises
    ------
    AgentSpecError
        An agent that cannot be used (with ``isolate``: one that cannot be pickled), a name against
        the rule, or two agents with one name.
    UnknownSuiteError
        An unknown ``suite`` (nothing is run or written).
    SettingError
        An unknown setting, or ``agentic`` with a setting that has no governed counterpart.
    AgentFailure
        A user agent's code raised, or it returned an invalid action or ``end_episode`` value
        (one line naming the agent, run seed, episode and step); nothing is published.

    Notes
    -----
    ``solarchain-eval evaluate``'s ``--planner``, ``--auditor``, ``--diagnostics`` and ``--llm-*``
    options are fields of ``agentic`` and ``llm``. Two of its options have no parameter here:
    ``--vecnormalize`` (give an agent that normalises the observation with the statistics before
    calling ``model.predict``) and ``--llm-concurrency`` (episodes run one at a time).
    """
    agents = list(agent) if isinstance(agent, list | tuple) else [agent]
    if name is not None:
        problem = name_problem(name)  # the command line's rule (``NAME=spec``), checked before anything else
        if problem is not None:
            raise AgentSpecError(f"name=: {problem}")
        if len(agents) != 1:
            raise AgentSpecError("name= names a single agent; give each of several agents its own name attribute")
        from ..agents.adapters import as_agent

        agents = [as_agent(agents[0], name=name) if not isinstance(agents[0], str) else f"{name}={agents[0]}"]
    if suite is not None:
        return _evaluate_suite(
            suite,
            agents,
            data=data,
            task=task,
            out=out,
            overwrite=overwrite,
            on_episode=on_episode,
            spec_options=dict(
                run_seeds=tuple(int(s) for s in seeds),
                episodes=int(episodes),
                config=config,
                models=dict(models or {}),
                agentic=agentic,
                setting=setting,
                agent_args=dict(agent_args or {}),
                llm=llm,
                isolate=isolate,
            ),
        )
    spec = EvaluationSpec(
        policies=agents,
        run_seeds=tuple(int(s) for s in seeds),
        episodes=int(episodes),
        data_dir=Path(data) if data is not None else None,
        config=config,  # None: the task's default configuration
        models=dict(models or {}),
        agentic=agentic,
        setting=setting,
        agent_args=dict(agent_args or {}),
        llm=llm,
        isolate=isolate,
        task=task,
    )
    scratch = None if out is not None else Path(tempfile.mkdtemp(prefix="solarchain-evaluate-"))
    target = Path(out) if out is not None else scratch / "run"  # type: ignore[operator]
    try:
        outcome = run_evaluation(
            spec, target, on_episode=on_episode, command=["solarchain_eval.evaluate"], overwrite=overwrite
        )
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
    metrics = metrics_frame(outcome.results, get_task(task))
    return Evaluation(
        metrics=metrics,
        summary=summary_frame(summarize(metrics)),
        run_dir=outcome.run_dir if out is not None else None,
        protocol_id=outcome.protocol_id,
        protocol=outcome.protocol,
        access=outcome.access,
        wall_s=outcome.wall_s,
        episodes=outcome.results,
    )


def _evaluate_suite(
    suite: str,
    agents: list[Any],
    *,
    data: str | Path | None,
    task: str,
    out: str | Path | None,
    overwrite: bool,
    on_episode: Callable[[EpisodeResult], None] | None,
    spec_options: dict[str, Any],
) -> SuiteEvaluation:
    """:func:`evaluate` with ``suite``: one run per entry (docs/suites.md)."""
    chosen = get_suite(suite)  # an unknown name: one line, before anything is run
    if data is not None or task != DEFAULT_TASK:
        raise SuiteError(f"suite={suite!r} names its tasks and datasets; give neither data= nor task=")

    def make_spec(entry: SuiteEntry, data_dir: Path, policies: list[Any]) -> EvaluationSpec:
        options = {**spec_options, "config": entry.configure(spec_options.get("config"))}
        return EvaluationSpec(policies=policies, data_dir=data_dir, task=entry.task, **options)

    def run(spec: EvaluationSpec, run_dir: Path):
        command = ["solarchain_eval.evaluate", f"suite={suite}"]
        return run_evaluation(spec, run_dir, on_episode=on_episode, command=command, overwrite=overwrite)

    scratch = None if out is not None else Path(tempfile.mkdtemp(prefix="solarchain-suite-"))
    target = Path(out) if out is not None else scratch / "suite"  # type: ignore[operator]
    try:
        result = run_suite(
            chosen, agents, make_spec, run, target, overwrite=overwrite, command=["solarchain_eval.evaluate"]
        )
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
    if out is None:
        result.root = None
    return result
