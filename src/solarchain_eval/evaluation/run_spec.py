"""What an evaluation is asked to run (:class:`EvaluationSpec`) and what a published run yields
(:class:`EvaluationOutcome`), with the spec's resolved task configuration.

:func:`~.runner.run_evaluation` runs a spec; :mod:`.agent_setup` builds and checks its agents.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..agents.base import Policy
from ..governance.factory import AgenticOptions, LLMOptions
from ..protocol import PAPER_EPISODES, PAPER_SEEDS, paper_episode_seeds
from ..tasks.registry import DEFAULT_TASK, get_task
from .rollout import EpisodeResult
from .setting_resolution import resolve_setting
from .settings import Setting


@dataclass
class EvaluationSpec:
    """What to evaluate.

    ``policies`` are agent specs (built-in names such as ``"static"``, ``"pkg.module:attr"``,
    ``"NAME=http://..."``: :mod:`solarchain_eval.agents.specs`) or agents (objects with ``act``,
    functions ``observation -> action``, Stable-Baselines3 models). Their names must be unique.
    ``task`` names the market (:func:`~solarchain_eval.tasks.registry.get_task`); ``config`` is that
    task's configuration (None: its default, for the solar market ``BenchmarkConfig()``), and a
    task other than the solar market offers its own baselines by name (``Task.baselines``).

    ``setting`` (a :class:`~solarchain_eval.evaluation.settings.Setting` or a registered name)
    fixes the reward, the governance and the config overrides; once built, ``setting`` is its
    name, and ``no_physics_penalty`` and ``agentic`` are what it runs with. Without it, as
    before: with ``agentic`` set, every policy is wrapped by the Planner/Auditor layer and the
    setting is ``llm`` (``llm_no_physics`` with ``no_physics_penalty``); ``setting_label`` names a
    registered setting whose reward and governance must agree with those two.
    (:func:`~solarchain_eval.evaluation.setting_resolution.resolve_setting` reconciles them.)
    """

    policies: Sequence[str | Policy]
    run_seeds: Sequence[int] = PAPER_SEEDS
    episodes: int = PAPER_EPISODES
    data_dir: Path | None = None
    #: The reward switch (None: the setting's; False without a setting).
    no_physics_penalty: bool | None = None
    #: The task's configuration (None: ``get_task(task).default_config()``, set on construction).
    config: Any = None
    models: dict[str, Path] = field(default_factory=dict)
    episode_seeds: Callable[[int, int], list[int]] = paper_episode_seeds
    agentic: AgenticOptions | None = None
    #: Episodes in flight (threads; see :mod:`.inflight`). The results do not depend on it.
    concurrency: int = 1
    #: A registered setting's name for the records (None: the paper's setting of this reward and governance).
    setting_label: str | None = None
    #: ``--agent-arg`` options for agents built from classes and factories, by agent name (None: all).
    agent_args: dict[str | None, dict[str, Any]] = field(default_factory=dict)
    #: VecNormalize statistics for ``sb3:`` agents, by agent name (None: the only one).
    vecnormalize: dict[str | None, Path] = field(default_factory=dict)
    #: The endpoint of the ``llm-agent`` baseline (needed when it is among the policies).
    llm: LLMOptions | None = None
    #: Run user agents (Python objects, ``module:attr``, ``file.py:attr``, plugins, ``sb3:``) each in a
    #: process of its own (:mod:`~solarchain_eval.agents.isolated`); built-ins stay in this process.
    isolate: bool = False
    #: The market evaluated, by name (:mod:`solarchain_eval.tasks`).
    task: str = DEFAULT_TASK
    #: The setting (a Setting or a registered name); its name once the spec is built.
    setting: Setting | str | None = None
    _setting: Setting = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.config is None:  # an unknown task name is refused here, before any work
            self.config = get_task(self.task).default_config()
        self._setting, self.agentic = resolve_setting(
            self.setting, label=self.setting_label, no_physics_penalty=self.no_physics_penalty, agentic=self.agentic
        )
        self.setting = self._setting.name
        self.no_physics_penalty = self._setting.no_physics_penalty

    @property
    def setting_spec(self) -> Setting:
        """The resolved :class:`~solarchain_eval.evaluation.settings.Setting`."""
        return self._setting

    def run_config(self) -> Any:
        """The config the evaluation runs: ``config`` with the setting's reward switch and overrides."""
        return self._setting.apply(self.config, get_task(self.task))


@dataclass
class EvaluationOutcome:
    """A published run: its directory, episodes, files, wall time and protocol."""

    run_dir: Path
    results: list[EpisodeResult]
    files: dict[str, Path]
    wall_s: float
    #: The protocol fingerprint (:mod:`.fingerprint`) and its short id.
    protocol: dict[str, Any] = field(default_factory=dict)
    protocol_id: str = ""
    #: Policy name -> "isolated", "in-process" or "privileged" (:func:`~solarchain_eval.agents.base.access_label`).
    access: dict[str, str] = field(default_factory=dict)
    #: What ``summary.json`` holds, and the number of episodes run (also when ``results`` was not kept).
    summary: list[dict[str, Any]] = field(default_factory=list)
    episodes: int = 0


def dataset_provenance(data: Any) -> dict[str, Any]:
    """Where the solar market's dataset ``data`` came from (``Task.provenance`` of the default task)."""
    return get_task().provenance(data)


def resolved_config(spec: EvaluationSpec) -> Any:
    """The spec's task configuration with its setting's reward switch and config overrides applied."""
    return spec.run_config()
