"""Agent specs: how the command line (and :func:`solarchain_eval.evaluate`) names an agent.

A spec is one item of ``--policies`` (comma-separated), optionally prefixed ``NAME=`` to name the
row it produces:

==================================  ===========================================================
``static``, ``ppo``, ...            a built-in baseline or learned policy (case-insensitive)
``llm-agent``                       the LLM choosing every hour's action (needs an endpoint)
``package.module:attr``             an importable class, factory, function or agent object
``path/to/file.py:attr``            the same, from a Python file
``NAME`` of an installed plugin     an entry point of the group ``solarchain_eval.agents``
``NAME=sb3:ALGO:PATH.zip``          a Stable-Baselines3 / sb3-contrib model of any algorithm
``NAME=http://HOST:PORT/PATH``      an agent behind HTTP (:mod:`.http_agent`)
==================================  ===========================================================

``attr`` may be a class (instantiated with the ``--agent-arg`` options), a factory (a function
without required arguments, called with them), a function ``observation -> action``, or a ready
agent object. Spec text keeps its case (``file.py:MyAgent``); only built-in names are folded.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.metadata
import importlib.util
import inspect
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..common.errors import NamesOptions
from .adapters import AgentError, describe_exception, is_observation_function
from .names import NAME_RULE, is_valid_name

#: The entry-point group installed packages register agents in (``NAME = "pkg.module:attr"``).
ENTRY_POINT_GROUP = "solarchain_eval.agents"
#: The built-in LLM agent (built by the evaluation runner, which owns the model endpoint).
LLM_AGENT = "llm-agent"
AGENT_KINDS = ("builtin", "llm", "python", "file", "plugin", "sb3", "http")
#: What may stand before ``=`` in ``NAME=spec`` (the naming rule of :mod:`.names` is checked after).
_NAME_PREFIX = re.compile(r"^[^=:/\\]+$")


class AgentSpecError(NamesOptions, AgentError):
    """A spec that cannot be read, imported or built (one line, before any work).

    ``user_error`` keeps the exception the user's code raised (an import, a constructor), for
    ``SOLARCHAIN_DEBUG=1`` to show its traceback.
    """

    user_error: BaseException | None = None


def _user_code_failed(message: str, error: BaseException) -> AgentSpecError:
    failure = AgentSpecError(message)
    failure.user_error = error
    return failure


@dataclass(frozen=True)
class AgentSpec:
    """One parsed spec.

    Attributes
    ----------
    text : str
        The spec as given.
    name : str or None
        The row name (None: the agent's own ``name``, else its attribute or plugin name).
    kind : str
        One of :data:`AGENT_KINDS`.
    target : str
        What the kind points at: a built-in name, ``module:attr``, ``file.py:attr``, a plugin
        name, ``ALGO:PATH`` or a URL.
    """

    text: str
    name: str | None
    kind: str
    target: str

    @property
    def label(self) -> str:
        """The row name when the spec fixes it, else a readable stand-in for messages."""
        return self.name or self.target


def check_name(name: str, spec: str) -> str:
    """``name`` if it follows the naming rule (:mod:`.names`), else an :class:`AgentSpecError` naming ``spec``."""
    if not is_valid_name(name):
        raise AgentSpecError(f"agent name {name!r} in {spec!r}: {NAME_RULE}")
    return name


def parse_agent_spec(text: str, builtins: tuple[str, ...]) -> AgentSpec:
    """Read one spec (see the module docstring); ``builtins`` are the built-in names."""
    raw = text.strip()
    if not raw:
        raise AgentSpecError("empty agent spec")
    name: str | None = None
    head, sep, rest = raw.partition("=")
    if sep and _NAME_PREFIX.match(head.strip()):
        name, raw = check_name(head.strip(), text), rest.strip()
        if not raw:
            raise AgentSpecError(f"agent spec {text!r} names an agent but gives nothing after '='")
    lowered = raw.lower()
    if lowered.startswith(("http://", "https://")):
        if name is None:
            raise AgentSpecError(f"an agent behind HTTP needs a name: NAME={raw}")
        return AgentSpec(text, name, "http", raw)
    if lowered.startswith("sb3:"):
        algo, _, path = raw[4:].partition(":")
        if not algo or not path:
            raise AgentSpecError(f"agent spec {text!r}: write sb3:ALGO:PATH.zip (e.g. mine=sb3:TQC:models/tqc.zip)")
        return AgentSpec(text, name or Path(path).stem, "sb3", f"{algo}:{path}")
    if lowered in builtins:
        return AgentSpec(text, name or lowered, "builtin", lowered)
    if lowered == LLM_AGENT:
        return AgentSpec(text, name or LLM_AGENT, "llm", LLM_AGENT)
    if ":" in raw:
        location, _, attr = raw.rpartition(":")
        if not location or not attr:
            raise AgentSpecError(f"agent spec {text!r}: write package.module:attr or path/to/file.py:attr")
        is_file = location.endswith(".py") or "/" in location or "\\" in location
        return AgentSpec(text, name, "file" if is_file else "python", raw)
    if raw in plugin_names():
        return AgentSpec(text, name or raw, "plugin", raw)
    plugins = plugin_names()
    known = ", ".join([*builtins, LLM_AGENT, *plugins])
    raise AgentSpecError(
        f"unknown policy {raw!r}: choose from {known}, or give package.module:attr, path/to/file.py:attr, "
        "NAME=sb3:ALGO:PATH.zip or NAME=http://HOST:PORT/PATH"
    )


def parse_agent_list(text: str, builtins: tuple[str, ...]) -> list[AgentSpec]:
    """The specs of a comma-separated ``--policies`` value; names fixed by the specs must be unique."""
    specs = [parse_agent_spec(part, builtins) for part in text.split(",") if part.strip()]
    if not specs:
        raise AgentSpecError("no policies given")
    check_unique([s.name for s in specs if s.name is not None])
    return specs


def check_unique(names: list[str]) -> None:
    """Refuse two agents whose names differ at most in case: their episodes would pool into one row."""
    seen: dict[str, str] = {}
    for name in names:
        other = seen.get(name.lower())
        if other is not None:
            detail = "twice" if other == name else f"twice ({other!r} and {name!r} differ only in case)"
            raise AgentSpecError(f"agent name {name!r} is used {detail}: give each agent its own name (NAME=spec)")
        seen[name.lower()] = name


def parse_agent_args(items: list[str], names: list[str]) -> dict[str | None, dict[str, Any]]:
    """``--agent-arg`` values: ``KEY=VALUE`` (every agent built from a class or factory) or
    ``NAME.KEY=VALUE`` (only agent NAME). VALUE is read as JSON when it is JSON (numbers, true,
    lists, quoted strings), else kept as text. Returned as {NAME or None: {KEY: VALUE}}."""
    args: dict[str | None, dict[str, Any]] = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise AgentSpecError(f"--agent-arg {item!r}: write KEY=VALUE or NAME.KEY=VALUE")
        owner: str | None = None
        prefix, dot, rest = key.rpartition(".")
        if dot and prefix in names:
            owner, key = prefix, rest
        if not key.isidentifier():
            raise AgentSpecError(f"--agent-arg {item!r}: {key!r} is not a keyword argument name")
        try:
            parsed: Any = json.loads(value)
        except ValueError:
            parsed = value
        args.setdefault(owner, {})[key] = parsed
    return args


def parse_vecnormalize(items: list[str], names: list[str]) -> dict[str | None, Path]:
    """``--vecnormalize`` values: ``PATH`` (the only ``sb3:`` agent) or ``NAME=PATH`` (agent NAME,
    one of ``names``). Returned as {NAME or None: PATH}."""
    stats: dict[str | None, Path] = {}
    for item in items:
        name, sep, path = item.partition("=")
        if sep and name in names:
            stats[name] = Path(path)
        else:
            stats[None] = Path(item)
    return stats


def plugin_names() -> tuple[str, ...]:
    """Names of the agents installed packages register (entry-point group :data:`ENTRY_POINT_GROUP`)."""
    return tuple(sorted({ep.name for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}))


def plugin_entry_point(name: str) -> importlib.metadata.EntryPoint:
    """The entry point that registers plugin agent ``name`` (the first, if several packages do)."""
    found = sorted(
        (ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP) if ep.name == name),
        key=lambda ep: ep.value,
    )
    if not found:
        raise AgentSpecError(f"no installed package registers the agent {name!r} (group {ENTRY_POINT_GROUP})")
    return found[0]


def load_target(spec: AgentSpec) -> tuple[Any, str]:
    """The Python object a ``python``, ``file`` or ``plugin`` spec points at, and its attribute name."""
    if spec.kind == "plugin":
        entry = plugin_entry_point(spec.target)
        try:
            return entry.load(), spec.target
        except (Exception, SystemExit) as error:  # a plugin's import can fail in any way, sys.exit included
            raise _user_code_failed(
                f"cannot load plugin agent {spec.target!r} ({entry.value}): {describe_exception(error)}", error
            ) from None
    location, _, attr = spec.target.rpartition(":")
    module = _load_file(location, spec) if spec.kind == "file" else _import_module(location, spec)
    obj: Any = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            where = location if spec.kind == "file" else f"module {location!r}"
            raise AgentSpecError(f"agent spec {spec.text!r}: {where} has no attribute {attr!r}")
        obj = getattr(obj, part)
    return obj, attr.rpartition(".")[2]


def _import_module(module: str, spec: AgentSpec) -> Any:
    try:
        return importlib.import_module(module)
    except (Exception, SystemExit) as error:  # ImportError, or whatever the module raises (sys.exit too)
        raise _user_code_failed(
            f"agent spec {spec.text!r}: cannot import {module!r}: {describe_exception(error)}", error
        ) from None


def _load_file(location: str, spec: AgentSpec) -> Any:
    path = Path(location).expanduser()
    if not path.is_file():
        raise AgentSpecError(f"agent spec {spec.text!r}: no such file {path}")
    if path.suffix != ".py":
        raise AgentSpecError(f"agent spec {spec.text!r}: {path} is not a Python file (write path/to/file.py:attr)")
    resolved = path.resolve()
    # A private module name per file, so two files named agent.py do not replace each other.
    module_name = f"solarchain_user_agent_{hashlib.sha256(str(resolved).encode()).hexdigest()[:12]}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    loader_spec = importlib.util.spec_from_file_location(module_name, resolved)
    if loader_spec is None or loader_spec.loader is None:
        raise AgentSpecError(f"agent spec {spec.text!r}: cannot load {path} as a Python module")
    module = importlib.util.module_from_spec(loader_spec)
    sys.path.insert(0, str(resolved.parent))  # the file may import modules beside it
    try:
        loader_spec.loader.exec_module(module)
    except SyntaxError as error:
        raise _user_code_failed(f"{path}:{error.lineno}: syntax error: {error.msg}", error) from None
    except (Exception, SystemExit) as error:  # whatever the file raises while it runs, sys.exit included
        raise _user_code_failed(
            f"agent spec {spec.text!r}: running {path} raised {describe_exception(error)}", error
        ) from None
    finally:
        sys.path.remove(str(resolved.parent))
    sys.modules[module_name] = module
    return module


def instantiate(target: Any, attr: str, spec: AgentSpec, kwargs: dict[str, Any]) -> Any:
    """The agent a loaded target gives: a class or factory called with ``kwargs``, a function or
    an agent object as it is (these take no ``--agent-arg``)."""
    if inspect.isclass(target) or (callable(target) and not is_observation_function(target) and not _is_agent(target)):
        try:
            inspect.signature(target).bind(**kwargs)
        except TypeError as error:
            raise AgentSpecError(
                f"agent spec {spec.text!r}: {attr}() does not accept {sorted(kwargs)}: {error}"
            ) from None
        except ValueError:
            pass  # no signature (a builtin): let the call decide
        try:
            return target(**kwargs)
        except (Exception, SystemExit) as error:  # the user's constructor can fail in any way
            raise _user_code_failed(
                f"agent spec {spec.text!r}: {attr}() raised {describe_exception(error)}", error
            ) from None
    if kwargs:
        raise AgentSpecError(
            f"agent spec {spec.text!r}: {attr} is not a class or factory, so --agent-arg {', '.join(sorted(kwargs))} "
            "cannot be passed to it"
        )
    return target


def _is_agent(obj: Any) -> bool:
    return callable(getattr(obj, "act", None)) or callable(getattr(obj, "predict", None))
