"""Command-line options of the Planner/Auditor layer, shared by the commands that evaluate.

The options are the fields of :class:`~solarchain_eval.governance.request.GovernanceRequest`:
:func:`governance_options` gives a command one option per field, in place of its
``governance: GovernanceRequest`` parameter, and passes the request built from them. Adding an
option is one field of that class; no command changes.
"""

from __future__ import annotations

import functools
import inspect
import typing
from collections.abc import Callable, Collection, Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any

import typer
from rich.table import Table

from ..common.errors import flag_of
from ..governance import AgenticOptions, LLMOptions
from ..governance.request import AGENTIC_MODES, GovernanceRequest, GovernanceRequestError
from ..llm import LLMError
from ..llm.serving import local_server
from .common import CliError, register_user_error

# An LLM failure fails the run with its one-line message (policy, episode, step).
register_user_error(LLMError, GovernanceRequestError)

__all__ = ["AGENTIC_MODES", "agentic_options", "agentic_table", "governance_options", "llm_agent_options", "serving"]
#: The help panel of the governance options (and of options that go with them, e.g. evaluate's --llm-concurrency).
PANEL = "Planner/Auditor (agentic settings)"
#: Default of a command's ``governance`` parameter, which :func:`governance_options` replaces.
GOVERNANCE: Any = None


def governance_options(
    *,
    only: Collection[str] | None = None,
    fixed: Mapping[str, Any] | None = None,
    unset: Mapping[str, str] | None = None,
) -> Callable[[Callable], Callable]:
    """Decorator: replace the command's ``governance`` parameter with the request's options.

    Parameters
    ----------
    only : collection of str, optional
        The fields the command offers as options (default: every field not in ``fixed``).
    fixed : mapping, optional
        Field values the command sets itself (e.g. ``bench-llm``'s ``planner="llm"``).
    unset : mapping, optional
        Fields whose option defaults to None, which the command resolves itself, each with the
        sentence its help adds on that default (e.g. ``bench-llm``'s ``llm_backend``).
    """
    fixed, unset = dict(fixed or {}), dict(unset or {})
    hints = typing.get_type_hints(GovernanceRequest)
    offered = [f for f in fields(GovernanceRequest) if (only is None or f.name in only) and f.name not in fixed]

    def decorate(func: Callable) -> Callable:
        signature = inspect.signature(func, eval_str=True)
        parameters = []
        for parameter in signature.parameters.values():
            if parameter.name != "governance":
                parameters.append(parameter)
                continue
            for f in offered:
                decls = f.metadata.get("param_decls", (flag_of(f.name),))  # e.g. an on/off pair of flags
                default, help, annotation = f.default, f.metadata["help"], hints[f.name]
                if f.name in unset:
                    default, help, annotation = None, f"{help} {unset[f.name]}", annotation | None
                option = typer.Option(default, *decls, help=help, rich_help_panel=PANEL)
                parameters.append(inspect.Parameter(f.name, parameter.kind, default=option, annotation=annotation))

        @functools.wraps(func)
        def command(*args: Any, **kwargs: Any) -> Any:
            given = {f.name: kwargs.pop(f.name) for f in offered}
            return func(*args, governance=GovernanceRequest(**fixed, **given), **kwargs)

        command.__signature__ = signature.replace(parameters=parameters)  # type: ignore[attr-defined]
        command.__annotations__ = {p.name: p.annotation for p in parameters} | {"return": signature.return_annotation}
        return command

    return decorate


def resolve(request: GovernanceRequest) -> AgenticOptions | None:
    """``request.resolve()``, its option errors named by flag (a :class:`CliError`)."""
    try:
        return request.resolve()
    except GovernanceRequestError as error:
        raise CliError(error.message_for(flag_of)) from None


def agentic_options(**values: Any) -> AgenticOptions | None:
    """Validated options from option values by field name, or None when ``agentic`` is ``none``."""
    return resolve(GovernanceRequest(**values))


def llm_agent_options(governance: GovernanceRequest) -> LLMOptions:
    """The LLM agent's endpoint settings and cache (``--policies llm-agent``), from the same
    ``--llm-*`` options as ``--planner llm`` (``--llm-backend``, ``--llm-api``, ``--llm-model``,
    ``--llm-cache``, ...) but without ``--agentic``; option errors named by flag (a :class:`CliError`).
    With ``--llm-backend local`` it names the port of the server :func:`serving` starts."""
    try:
        return governance.llm_options()
    except GovernanceRequestError as error:
        raise CliError(error.message_for(flag_of)) from None


def local_server_spec(params: dict[str, Any], options: AgenticOptions | None) -> local_server.ServerSpec | None:
    """The server to start for option values by field name (see :meth:`GovernanceRequest.server_spec`);
    ``llm_concurrency`` (evaluate's, not a request field) sets the server's parallel requests."""
    names = GovernanceRequest.field_names()
    request = GovernanceRequest(**{k: v for k, v in params.items() if k in names})
    return request.server_spec(options, parallel=int(params.get("llm_concurrency") or 1))


def serving(request: GovernanceRequest, options: AgenticOptions | None, *, parallel: int = 1, needs_llm: bool = False):
    """Context manager: the local model server the command needs, running (or nothing); it takes
    ``parallel`` requests at once (``evaluate --llm-concurrency``) without interrupting one.
    ``needs_llm``: a policy calls the model (the LLM agent), so ``--llm-backend local`` starts the
    server even without an LLM planner or auditor (one server for all of them)."""
    import tempfile

    spec = request.server_spec(options, parallel=parallel, needs_llm=needs_llm)
    log = Path(tempfile.gettempdir()) / f"solarchain-llm-server-{spec.port}.log" if spec is not None else None
    return local_server.serving(spec, log_path=log)


def agentic_table(summary: list[dict[str, Any]], title: str) -> Table:
    """Mean agentic metrics per policy and setting (rows without them are skipped)."""
    table = Table(title=title, title_justify="left")
    columns = (
        ("audit rate", "audit_rate"),
        ("revision rate", "revision_rate"),
        ("modification rate", "modification_rate"),
        ("mean action delta", "mean_action_delta"),
        ("hard trigger rate", "hard_trigger_rate"),
        ("LLM retries", "llm_retry_count"),
    )
    table.add_column("policy")
    table.add_column("setting")
    for label, _ in columns:
        table.add_column(label, justify="right")
    for entry in summary:
        metrics = entry["metrics"]
        if "audit_rate" not in metrics:
            continue
        table.add_row(entry["policy"], entry["setting"], *(f"{metrics[key]['mean']:.4f}" for _, key in columns))
    return table
