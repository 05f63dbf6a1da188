"""The experiment grid of ``solarchain-eval paper``: settings, presets, episode seeds, units.

A grid is a list of *units*, each one directory under ``ROOT/units`` (see :mod:`.layout`):

- train units ``train/<algo>-<setting>-<seed>``: one model per algorithm × training setting ×
  seed (``main`` trains with the physics penalty, ``no_physics`` without), trained with the
  grid's backend (``sb3``, or ``jax``: rejax on the JAX environment, docs/jax.md). With the JAX
  backend one train unit ``train/<algo>-<setting>-<seed>+<seed>+...`` trains every seed of an
  algorithm and setting in one ``vmap``, each model in ``seed_<seed>/`` of the unit;
- eval units ``eval/<policy>-<setting>-<seed>``: one policy evaluated in one setting for one
  run seed over the grid's episodes. An eval unit of a learned policy depends on the train unit
  of the same algorithm, seed and the setting's ``model_setting``.

User agents (``GridSpec.agents``: agent specs, :mod:`.agents`) get eval units only, named by the
agent, in every setting of the grid (behind the Planner/Auditor layer in the agentic ones) after
the built-in policies.

Settings are :data:`~solarchain_eval.evaluation.settings.KNOWN_SETTINGS`: ``main`` and
``no_physics`` evaluate every policy; the agentic settings ``llm`` (models trained in ``main``) and
``llm_no_physics`` (models from ``no_physics``) evaluate the learned policies behind the
Planner/Auditor layer, whose planner and auditor kinds are the grid's
:class:`~solarchain_eval.governance.AgenticOptions` (rule by default).
:func:`~solarchain_eval.evaluation.settings.register_setting` adds more.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..agents.checkpoints import OPT_IN_ALGOS, TRAINABLE_ALGOS
from ..config import BenchmarkConfig
from ..evaluation.settings import (
    KNOWN_SETTINGS,
    SETTING_AGENTIC,
    SETTING_AGENTIC_NO_PHYSICS,
    SETTING_MAIN,
    SETTING_NO_PHYSICS,
    TRAIN_SETTINGS,
)
from ..governance.factory import AgenticOptions
from ..protocol import EPISODE_SEED_RULES, PAPER_EPISODES, PAPER_SEEDS, PAPER_TIMESTEPS, independent_episode_seeds
from ..tasks.base import has_jax_env
from ..tasks.governance_view import GovernedTask
from ..tasks.registry import DEFAULT_TASK, get_task
from ..training.lagrangian import DEFAULT_COST_LIMIT, LagrangianSettings
from ..training.sb3_spec import DEFAULT_CHECKPOINT_EVERY
from .layout import UNITS_DIR, eval_unit_dir, seed_model_dir, train_unit_dir

#: Training backends of the grid's train units.
BACKENDS = ("sb3", "jax")


@dataclass(frozen=True)
class Preset:
    timesteps: int
    episodes: int
    seeds: tuple[int, ...]
    checkpoint_every: int


PRESETS = {
    "paper": Preset(PAPER_TIMESTEPS, PAPER_EPISODES, PAPER_SEEDS, DEFAULT_CHECKPOINT_EVERY),
    # Tiny budgets that exercise every stage (PPO still collects one 2,048-step rollout).
    "smoke": Preset(300, 2, PAPER_SEEDS[:1], DEFAULT_CHECKPOINT_EVERY),
}


def task_policies(policies: tuple[str, ...], task: str) -> tuple[str, ...]:
    """A setting's policy list for ``task``: the default task's baselines it lists (the paper's
    settings list the solar market's) stand for the baselines of ``task``, in their place."""
    if task == DEFAULT_TASK:
        return tuple(policies)
    default, own = set(get_task().baselines()), tuple(get_task(task).baselines())
    listed: list[str] = []
    for policy in policies:
        if policy not in default:
            listed.append(policy)
        elif not set(own) <= set(listed):
            listed.extend(own)
    return tuple(dict.fromkeys(listed))


@dataclass(frozen=True)
class GridSpec:
    """What ``paper`` runs: budgets, seeds, settings, policies and the dataset."""

    timesteps: int
    episodes: int
    seeds: tuple[int, ...]
    settings: tuple[str, ...] = (SETTING_MAIN, SETTING_NO_PHYSICS, SETTING_AGENTIC, SETTING_AGENTIC_NO_PHYSICS)
    episode_seed_protocol: str = "paper"
    data_dir: Path | None = None
    config: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    checkpoint_every: int = DEFAULT_CHECKPOINT_EVERY
    preset: str | None = None
    policies: tuple[str, ...] | None = None  # None: every non-opt-in policy of each setting
    agentic: AgenticOptions = field(default_factory=AgenticOptions)  # the agentic settings' layer
    backend: str = "sb3"  # the train units' backend: "sb3" or "jax"
    lagrangian: LagrangianSettings = field(default_factory=lambda: LagrangianSettings(DEFAULT_COST_LIMIT))
    #: Per-setting policy lists ((setting, policies), ...) that override ``policies`` there
    #: (they may name user agents, which then run in those settings only).
    policies_by_setting: tuple[tuple[str, tuple[str, ...]], ...] = ()
    #: User agents ((name, agent spec text), ...): evaluated, never trained, in every setting.
    agents: tuple[tuple[str, str], ...] = ()
    #: ``--agent-arg`` options of the user agents by name (None: every agent built from a class or factory).
    agent_args: dict[str | None, dict[str, Any]] = field(default_factory=dict)
    #: VecNormalize statistics of ``sb3:`` user agents by name (None: the only one).
    vecnormalize: dict[str | None, Path] = field(default_factory=dict)
    #: Run the user agents' eval units with each agent in a process of its own (``--isolate``).
    isolate: bool = False
    #: JAX train units: env steps per compiled chunk, after which progress is reported and the
    #: train state checkpointed (None: the algorithm's default). The models do not depend on it,
    #: so it is not part of the grid's identity.
    chunk_steps: int | None = None
    #: The task every unit trains and evaluates on (part of the identity when it is not the solar market).
    task: str = DEFAULT_TASK

    def setting_policies(self, setting: str) -> tuple[str, ...]:
        """The built-in policies evaluated in ``setting`` (:meth:`setting_agents` adds the user agents)."""
        listed = task_policies(KNOWN_SETTINGS[setting].policies, self.task)
        chosen = dict(self.policies_by_setting).get(setting)
        if chosen is not None:
            return tuple(p for p in listed if p in chosen)
        if self.policies is None:
            return tuple(p for p in listed if p not in OPT_IN_ALGOS)
        return tuple(p for p in listed if p in self.policies)

    def setting_agents(self, setting: str) -> tuple[str, ...]:
        """The names of the user agents evaluated in ``setting``."""
        chosen = dict(self.policies_by_setting).get(setting)
        return tuple(name for name, _ in self.agents if chosen is None or name in chosen)

    def agent_spec(self, name: str) -> str | None:
        """The spec text of user agent ``name`` (None for a built-in policy)."""
        return dict(self.agents).get(name)

    @property
    def uses_lagrangian(self) -> bool:
        return any("ppo-lag" in self.setting_policies(s) for s in self.settings)

    @classmethod
    def from_preset(cls, name: str, **overrides: Any) -> GridSpec:
        if name not in PRESETS:
            raise ValueError(f"unknown preset '{name}' (choose from {', '.join(PRESETS)})")
        p = PRESETS[name]
        values: dict[str, Any] = {
            "timesteps": p.timesteps,
            "episodes": p.episodes,
            "seeds": p.seeds,
            "checkpoint_every": p.checkpoint_every,
        }
        values.update({k: v for k, v in overrides.items() if v is not None})
        return cls(preset=name, **values)

    def validate(self) -> None:
        if self.timesteps < 1 or self.episodes < 1 or not self.seeds:
            raise ValueError("timesteps and episodes must be at least 1, and at least one seed is needed")
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown backend '{self.backend}' (choose from {', '.join(BACKENDS)})")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"a seed is listed twice: {list(self.seeds)}")
        unknown = [s for s in self.settings if s not in KNOWN_SETTINGS]
        if unknown:
            raise ValueError(f"unknown setting(s) {', '.join(unknown)} (registered: {', '.join(KNOWN_SETTINGS)})")
        if self.chunk_steps is not None and (self.chunk_steps < 1 or self.backend != "jax"):
            raise ValueError(f"chunk_steps ({self.chunk_steps}) must be at least 1 and needs the jax backend")
        if self.backend != "sb3" and self.uses_lagrangian:
            raise ValueError("ppo-lag trains with the sb3 backend only")
        governed = [s for s in self.settings if KNOWN_SETTINGS[s].agentic]
        if governed and not isinstance(get_task(self.task), GovernedTask):
            raise ValueError(
                f"settings {', '.join(governed)} run the Planner/Auditor layer, and task {self.task!r} supplies no "
                "governance view (solarchain_eval.tasks.governance_view)"
            )
        if self.backend == "jax" and not has_jax_env(get_task(self.task)):
            raise ValueError(f"the jax backend needs a JAX environment, and task {self.task!r} has none")
        if self.agents:
            from .user_agents import check_agent_names  # the agent registry, only for grids with user agents

            check_agent_names(self.agents, self.policies or ())
        if self.policies is not None:
            offered = {p for s in self.settings for p in KNOWN_SETTINGS[s].policies}
            unknown = [p for p in self.policies if p not in offered]
            if unknown or not (self.policies or self.agents):
                raise ValueError(
                    f"unknown or no policies {', '.join(unknown)} (the settings offer {', '.join(sorted(offered))})"
                )
        names = [name for name, _ in self.agents]
        for setting, chosen in self.policies_by_setting:
            offered = (*KNOWN_SETTINGS[setting].policies, *names) if setting in KNOWN_SETTINGS else ()
            unknown = [p for p in chosen if p not in offered]
            if setting not in self.settings or unknown or not chosen:
                raise ValueError(f"policies of setting '{setting}': {', '.join(unknown) or 'none'} not offered there")
        for setting in self.settings:  # a setting with nothing to evaluate would have nothing to combine
            if not (self.setting_policies(setting) or self.setting_agents(setting)):
                offered = ", ".join(KNOWN_SETTINGS[setting].policies)
                raise ValueError(
                    f"setting '{setting}' would evaluate no policy: choose some of {offered} there, or drop the setting"
                )
        if self.episode_seed_protocol not in EPISODE_SEED_RULES:
            raise ValueError(
                f"unknown episode-seed protocol '{self.episode_seed_protocol}' (choose from {', '.join(EPISODE_SEED_RULES)})"
            )
        if self.episode_seed_protocol == "independent":
            seeds = [e for s in self.seeds for e in independent_episode_seeds(s, self.episodes)]
            if len(set(seeds)) != len(seeds):
                raise ValueError("the independent episode seeds of these run seeds collide; pick other run seeds")

    def episode_seeds(self) -> Callable[[int, int], list[int]]:
        return EPISODE_SEED_RULES[self.episode_seed_protocol]


@dataclass(frozen=True)
class Unit:
    """One unit of work; ``name`` is its path under ``ROOT/units`` (``train/...`` or ``eval/...``).

    ``scope`` places the unit in a sub-root: a sweep point's units live in
    ``ROOT/<scope>/units/...`` and their names start with ``<scope>/`` (empty for ``paper``).
    """

    kind: str
    policy: str
    setting: str
    seed: int
    depends_on: tuple[str, ...] = ()
    scope: str = ""  # a sweep point's sub-root ("" for a plain grid)
    backend: str = "sb3"  # train units: which library trains the model
    #: JAX train units: every seed trained together in one vmap (``seed`` is the first); empty
    #: for a unit of one seed, whose model is the unit directory's own.
    seed_group: tuple[int, ...] = ()

    @property
    def seed_label(self) -> str:
        return "+".join(str(s) for s in self.seed_group) if self.seed_group else str(self.seed)

    @property
    def name(self) -> str:
        local = f"{self.kind}/{self.policy}-{self.setting}-{self.seed_label}"
        return f"{self.scope}/{local}" if self.scope else local

    def directory(self, root: Path) -> Path:
        base = Path(root) / self.scope if self.scope else Path(root)
        if self.kind == "train":
            return train_unit_dir(base, self.policy, self.setting, self.seed_label)
        return eval_unit_dir(base, self.policy, self.setting, self.seed)

    def unscoped(self) -> Unit:
        """The unit as its own sub-root sees it."""
        prefix = f"{self.scope}/" if self.scope else ""
        deps = tuple(d[len(prefix) :] if prefix and d.startswith(prefix) else d for d in self.depends_on)
        return replace(self, depends_on=deps, scope="")


def scoped(units: list[Unit], scope: str) -> list[Unit]:
    """``units`` moved into the sub-root ``scope`` (dependencies renamed with them)."""
    return [replace(u, depends_on=tuple(f"{scope}/{d}" for d in u.depends_on), scope=scope) for u in units]


def train_unit(algo: str, setting: str, seed: int, backend: str = "sb3", seed_group: tuple[int, ...] = ()) -> Unit:
    return Unit("train", algo, setting, seed_group[0] if seed_group else seed, backend=backend, seed_group=seed_group)


def plan_units(spec: GridSpec) -> list[Unit]:
    """Every unit of the grid in a fixed order: train units (SAC first: the longest), then eval
    units by setting, policy (the user agents after the built-ins) and seed. Train units are
    planned only where an eval unit needs them.

    With the JAX backend the seeds of an algorithm and training setting form one train unit
    (rejax trains them in one ``vmap``, compiled once; on a GPU in about the time of one).
    """
    needed: dict[tuple[str, str], set[int]] = {}
    wanted: list[tuple[str, str, int]] = []
    for setting_name in spec.settings:
        setting = KNOWN_SETTINGS[setting_name]
        for policy in (*spec.setting_policies(setting_name), *spec.setting_agents(setting_name)):
            for seed in spec.seeds:
                wanted.append((policy, setting_name, seed))
                if policy in TRAINABLE_ALGOS:  # a user agent cannot take a built-in's name
                    needed.setdefault((policy, setting.model_setting), set()).add(seed)
    order = {algo: i for i, algo in enumerate(("sac", "ppo", "ppo-lag", "dqn"))}
    trains: dict[tuple[str, str, int], Unit] = {}
    for algo, setting in sorted(needed, key=lambda k: (order.get(k[0], 9), TRAIN_SETTINGS.index(k[1]))):
        seeds = sorted(needed[(algo, setting)])
        if spec.backend == "jax":
            group = train_unit(algo, setting, seeds[0], spec.backend, tuple(seeds))
            trains.update({(algo, setting, seed): group for seed in seeds})
        else:
            trains.update({(algo, setting, seed): train_unit(algo, setting, seed, spec.backend) for seed in seeds})
    evals = []
    for policy, setting_name, seed in wanted:
        train = trains.get((policy, KNOWN_SETTINGS[setting_name].model_setting, seed))
        evals.append(Unit("eval", policy, setting_name, seed, (train.name,) if train else ()))
    return list(dict.fromkeys(trains.values())) + evals


def eval_model_path(root: Path, unit: Unit, backend: str, model_file: str) -> Path | None:
    """The model file an eval unit loads (None for a baseline): its seed's, in its train unit.

    An SB3 train unit holds its one model; a JAX train unit (always a seed group, see
    :func:`plan_units`) holds each seed's in ``seed_<seed>/``.
    """
    if unit.kind != "eval" or not unit.depends_on:
        return None
    directory = Path(root) / UNITS_DIR / unit.depends_on[0]
    return (seed_model_dir(directory, unit.seed) if backend == "jax" else directory) / model_file
