"""User agents in the experiment grid (``paper``, ``sweep``) and the governance leaderboard.

Wherever these commands name policies they also take agent specs
(:mod:`solarchain_eval.agents.specs`: ``package.module:attr``, ``path/file.py:attr``, plugins,
``NAME=sb3:ALGO:PATH.zip``, ``NAME=http://...``). In a grid a user agent is evaluated, never
trained: one eval unit per setting and run seed, named like a built-in policy's
(``eval/<name>-<setting>-<seed>``), behind the Planner/Auditor layer in the agentic settings.

Units run in worker processes (local or Ray), so a unit carries the agent's spec *text* and
builds the agent there (:func:`worker_spec`). This module splits a policy list into built-ins
and agent specs, names the agents by building them once up front (which also checks imports,
models and action shapes before any work), and says what a unit records about its agent
(:func:`agent_identity`), so that resuming a grid redoes a unit whose agent changed.
"""

from __future__ import annotations

import importlib.util
import json
from collections.abc import Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..agents.build import build_agents
from ..agents.checkpoints import TRAINABLE_ALGOS
from ..agents.registry import known_policies
from ..agents.request import AgentContext, agent_requests
from ..agents.specs import (
    AgentSpec,
    AgentSpecError,
    check_name,
    check_unique,
    parse_agent_args,
    parse_agent_spec,
    plugin_entry_point,
)
from ..common.atomic_files import sha256_file
from ..common.redaction import redact_options, redact_spec
from ..config import BenchmarkConfig
from ..evaluation.agent_setup import check_agent_requests
from ..evaluation.reserved import check_reserved, reserved_names
from ..protocol import PAPER_SEED

#: A grid's user agents: (name, spec text) in the order given.
GridAgents = tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class PolicyChoice:
    """A policy list split into the grid's built-in policies and user agent specs."""

    builtins: tuple[str, ...]
    agents: tuple[AgentSpec, ...]


def split_policies(items: Sequence[str]) -> PolicyChoice:
    """Split ``items`` (each a built-in name or an agent spec) into built-ins and user agents.

    A built-in renamed with ``NAME=`` (``mine=static``) is a user agent; a learned built-in
    cannot be renamed (its models are the grid's own, found by its name), and the LLM agent
    runs in ``evaluate`` only.

    Raises
    ------
    AgentSpecError
        A spec that cannot be read, or a name fixed twice.
    """
    builtins = known_policies()
    specs = [parse_agent_spec(item, builtins) for item in items if item.strip()]
    check_unique([s.name for s in specs if s.name is not None])
    refuse_llm_agent(specs)
    chosen: list[str] = []
    agents: list[AgentSpec] = []
    for spec in specs:
        if spec.kind == "builtin" and spec.name == spec.target:
            chosen.append(spec.target)
        elif spec.kind == "builtin" and spec.target in TRAINABLE_ALGOS:
            raise AgentSpecError(
                f"{spec.text!r}: the grid trains and evaluates {spec.target} under its own name; list it as {spec.target}"
            )
        else:
            agents.append(spec)
    return PolicyChoice(tuple(chosen), tuple(agents))


def refuse_llm_agent(specs: Sequence[AgentSpec]) -> None:
    """The LLM agent needs a model endpoint of its own, which only ``evaluate`` sets up."""
    for spec in specs:
        if spec.kind == "llm":
            raise AgentSpecError(
                f"{spec.text!r}: the LLM agent runs in 'evaluate' only (it needs its own model endpoint)"
            )


def check_agent_names(agents: GridAgents, builtins: Sequence[str] = ()) -> None:
    """Refuse agent names that cannot name a unit directory, clash with a built-in policy
    (case-insensitive) or are used twice (among the agents and ``builtins``).

    Raises
    ------
    AgentSpecError
    """
    for name, text in agents:
        try:
            check_name(name, text)
        except AgentSpecError:
            raise AgentSpecError(
                f"agent {text!r} is named {name!r}, which cannot name its unit directories: "
                "give it a name of letters, digits and _ . + - (NAME=spec)"
            ) from None
        check_reserved(name)  # the rule of every evaluation (evaluation/reserved.py)
    check_unique([*builtins, *(name for name, _ in agents)])


def resolve_agents(
    specs: Sequence[AgentSpec],
    *,
    config: BenchmarkConfig,
    agent_args: Mapping[str | None, dict[str, Any]] | None = None,
    vecnormalize: Mapping[str | None, Path] | None = None,
    data_dirs: Sequence[Path | None] | None = None,
    run_seed: int = PAPER_SEED,
    builtins: Sequence[str] = (),
    isolate: bool = False,
) -> GridAgents:
    """Name the user agents of a grid by building each once, before any work.

    Parameters
    ----------
    specs : sequence of AgentSpec
        The user agents (:func:`split_policies`).
    config : BenchmarkConfig
    agent_args, vecnormalize : mapping, optional
        ``--agent-arg`` / ``--vecnormalize`` options by agent name (None: every agent).
    data_dirs : sequence, optional
        Datasets to try every agent's first action on
        (:func:`~solarchain_eval.evaluation.runner.check_agent_requests`; None in the sequence: the
        config's dataset). None: only build the agents (no dataset needed).
    run_seed : int
        The run seed of the first action tried.
    builtins : sequence of str
        The grid's built-in policies, whose names the agents may not take.
    isolate : bool
        Build and try each agent in a process of its own (``--isolate``): none of its code runs here.

    Returns
    -------
    tuple of (str, str)
        (name, spec text) per agent: the name the spec fixes, else the built agent's own.

    Raises
    ------
    AgentSpecError
        An import, constructor, model or action problem, or a name that is taken (one line).
    FileNotFoundError
        A missing model file.
    """
    if not specs:
        return ()
    requests = agent_requests(specs, agent_args=agent_args, vecnormalize=vecnormalize, isolate=isolate)
    context = AgentContext(config)
    if data_dirs is None:
        with ExitStack() as stack:
            names = [agent.name for agent in build_agents(requests, context, stack=stack, check_name=check_reserved)]
    else:
        for data_dir in data_dirs:
            names = check_agent_requests(requests, context, data_dir=data_dir, run_seed=run_seed)
    agents = tuple((name, spec.text) for name, spec in zip(names, specs, strict=True))
    check_agent_names(agents, builtins)
    return agents


def check_resolved(
    agents: GridAgents,
    *,
    config: BenchmarkConfig,
    agent_args: Mapping[str | None, dict[str, Any]] | None = None,
    vecnormalize: Mapping[str | None, Path] | None = None,
    data_dir: Path | None = None,
    run_seed: int = PAPER_SEED,
    isolate: bool = False,
) -> None:
    """Try the first action of named agents on ``data_dir`` (e.g. each dataset of a sweep), each in a
    process of its own with ``isolate``."""
    if not agents:
        return
    requests = agent_requests(
        [worker_spec(name, text) for name, text in agents],
        agent_args=agent_args,
        vecnormalize=absolute_paths(vecnormalize or {}),
        isolate=isolate,
    )
    check_agent_requests(requests, AgentContext(config), data_dir=data_dir, run_seed=run_seed)


@dataclass(frozen=True)
class GridPolicies:
    """A grid's policy lists as :class:`~.grid.GridSpec` takes them (a sweep's ``grid.policies``)."""

    policies: tuple[str, ...] | None = None  # built-in policies of one list for every setting (None: all)
    by_setting: tuple[tuple[str, tuple[str, ...]], ...] = ()  # a list per setting, user agents by name
    agents: GridAgents = ()
    agent_args: dict[str | None, dict[str, Any]] = field(default_factory=dict)
    vecnormalize: dict[str | None, Path] = field(default_factory=dict)


def grid_policies(
    policies: list[str] | dict[str, list[str]] | None,
    *,
    base: Path,
    config: BenchmarkConfig,
    agent_args: Mapping[str, Any] | None = None,
    vecnormalize: str | Mapping[str, str] | None = None,
    isolate: bool = False,
) -> GridPolicies:
    """Policy lists (one list, or a list per setting) of built-in names and agent specs, the
    agents named by building each once (no dataset needed; :func:`check_resolved` tries them).

    Parameters
    ----------
    policies : list, dict or None
        As a sweep's ``grid.policies``.
    base : Path
        The directory relative paths (``file.py``, ``sb3:`` models, ``vecnormalize``) start from.
    config : BenchmarkConfig
    agent_args : mapping, optional
        ``{KEY: VALUE}`` for every agent built from a class or factory, ``{NAME.KEY: VALUE}`` for agent NAME.
    vecnormalize : str or mapping, optional
        The only ``sb3:`` agent's VecNormalize statistics, or ``{NAME: PATH}``.
    isolate : bool
        Build each agent in a process of its own (``grid.isolate``).

    Raises
    ------
    AgentSpecError
        A spec that cannot be read or built, or a name that is taken.
    FileNotFoundError
        A missing model file.
    """
    if policies is None:
        return GridPolicies()
    lists = policies if isinstance(policies, dict) else {"": policies}
    items = [i.strip() for i in dict.fromkeys(i for items in lists.values() for i in items) if i.strip()]
    choice = split_policies(items)
    texts = {spec.text.strip(): rebase_spec(spec.text, base) for spec in choice.agents}
    named = [s.name for s in choice.agents if s.name is not None]
    # YAML values are typed already; through JSON they get --agent-arg's reading and checks
    args = parse_agent_args([f"{k}={json.dumps(v)}" for k, v in (agent_args or {}).items()], named)
    stats: Mapping[str | None, str] = (
        {None: vecnormalize} if isinstance(vecnormalize, str) else dict(vecnormalize or {})
    )
    paths = {name: Path(base) / Path(path).expanduser() for name, path in stats.items()}
    agents = resolve_agents(
        split_policies(list(texts.values())).agents,
        config=config,
        agent_args=args,
        vecnormalize=paths,
        builtins=choice.builtins,
        isolate=isolate,
    )
    name_of = dict(zip(texts, (name for name, _ in agents), strict=True))

    def grid_names(items: list[str]) -> tuple[str, ...]:
        return tuple(name_of.get(i.strip()) or split_policies([i]).builtins[0] for i in items if i.strip())

    if isinstance(policies, dict):
        by_setting = tuple((setting, grid_names(items)) for setting, items in policies.items())
        return GridPolicies(None, by_setting, agents, args, paths)
    return GridPolicies(choice.builtins, (), agents, args, paths)


def _parse(text: str) -> AgentSpec:
    return parse_agent_spec(text, known_policies())


def worker_spec(name: str, text: str) -> str:
    """The spec a worker builds the agent from: named ``name`` (so its records carry the grid's
    name whatever the worker's own agent says) with file paths made absolute (a Ray worker does
    not start in this directory)."""
    spec = _parse(text)
    if spec.kind == "file":
        location, _, attr = spec.target.rpartition(":")
        target = f"{Path(location).expanduser().absolute()}:{attr}"
    elif spec.kind == "sb3":
        algo, _, path = spec.target.partition(":")
        target = f"sb3:{algo}:{Path(path).expanduser().absolute()}"
    else:
        target = spec.target
    return f"{name}={target}"


def rebase_spec(text: str, base: Path) -> str:
    """``text`` with a relative ``file.py`` or ``sb3:`` path taken relative to ``base`` (a sweep
    YAML's directory, like its ``dataset.data``)."""
    spec = _parse(text)
    prefix = f"{spec.name}=" if spec.name is not None and text.strip().partition("=")[0].strip() == spec.name else ""
    if spec.kind == "file":
        location, _, attr = spec.target.rpartition(":")
        path = Path(location).expanduser()
        return text if path.is_absolute() else f"{prefix}{Path(base) / path}:{attr}"
    if spec.kind == "sb3":
        algo, _, location = spec.target.partition(":")
        path = Path(location).expanduser()
        return text if path.is_absolute() else f"{prefix}sb3:{algo}:{Path(base) / path}"
    return text


def absolute_paths(paths: Mapping[str | None, Path]) -> dict[str | None, Path]:
    return {name: Path(path).expanduser().absolute() for name, path in paths.items()}


def agent_kwargs(name: str, agent_args: Mapping[str | None, dict[str, Any]]) -> dict[str, Any]:
    """The ``--agent-arg`` options agent ``name`` is built with (every agent's, then its own)."""
    return {**agent_args.get(None, {}), **agent_args.get(name, {})}


def agent_identity(
    name: str,
    text: str,
    agent_args: Mapping[str | None, dict[str, Any]],
    vecnormalize: Mapping[str | None, Path],
) -> dict[str, Any]:
    """What a unit of user agent ``name`` records (``unit.json`` → ``agent``): its spec, options
    and the sha256 of the files it is built from (the Python file or the module's file, a
    plugin's module file and its distribution's version, the SB3 model, the VecNormalize
    statistics). A done unit whose record differs is redone. An HTTP agent is recorded by its
    URL only: what the server runs is outside the grid's view. Secrets are recorded redacted
    (:mod:`~solarchain_eval.common.redaction`): the spec's URL credentials and the value of an
    option named like a key or token, so a change of only such a value does not redo a unit."""
    spec = _parse(text)
    files: dict[str, str] = {}
    record: dict[str, Any] = {}
    if spec.kind == "file":
        files["source"] = _digest(Path(spec.target.rpartition(":")[0]))
    elif spec.kind == "python":
        origin = _module_file(spec.target.rpartition(":")[0])
        if origin is not None:
            files["source"] = _digest(origin)
    elif spec.kind == "plugin":
        entry = plugin_entry_point(spec.target)
        origin = _module_file(entry.module)
        if origin is not None:
            files["source"] = _digest(origin)
        record["plugin"] = {"entry_point": entry.value, "version": entry.dist.version if entry.dist else None}
    elif spec.kind == "sb3":
        files["model"] = _digest(Path(spec.target.partition(":")[2]))
        stats = vecnormalize.get(name) or vecnormalize.get(None)
        if stats is not None:
            files["vecnormalize"] = _digest(Path(stats))
    args = redact_options(agent_kwargs(name, agent_args))
    return {"spec": redact_spec(text), "kind": spec.kind, "args": args, "sha256": files, **record}


def _module_file(module: str) -> Path | None:
    """The file of an importable module (None for a namespace or built-in module)."""
    try:
        found = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    origin = getattr(found, "origin", None)
    return Path(origin) if origin and Path(origin).is_file() else None


def _digest(path: Path) -> str:
    path = path.expanduser()
    return sha256_file(path) if path.is_file() else "missing"


__all__ = [
    "GridAgents",
    "GridPolicies",
    "PolicyChoice",
    "agent_identity",
    "agent_kwargs",
    "check_agent_names",
    "check_resolved",
    "grid_policies",
    "rebase_spec",
    "refuse_llm_agent",
    "reserved_names",
    "resolve_agents",
    "split_policies",
    "worker_spec",
]
