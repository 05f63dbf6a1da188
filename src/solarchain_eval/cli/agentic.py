"""Command-line options of the Planner/Auditor layer, shared by the commands that evaluate.

The options are module-level ``typer.Option`` objects so every command declares them the same
way; :func:`agentic_options` turns their values into
:class:`~solarchain_eval.agentic.AgenticOptions` (or None without ``--agentic``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import typer
from rich.table import Table

from ..agentic import AgenticOptions, LLMError, LLMOptions, resolve_llm_settings
from ..agentic.auditor import AUDITOR_KINDS
from ..agentic.cache import CACHE_MODES
from ..agentic.llm_client import DEFAULT_MAX_OUTPUT_TOKENS, DEFAULT_MAX_RETRIES, DEFAULT_TIMEOUT_S, LLM_APIS
from ..agentic.planner import PLANNER_KINDS
from .common import CliError, register_user_error

# An LLM failure fails the run with its one-line message (policy, episode, step).
register_user_error(LLMError)

AGENTIC_MODES = ("none", "planner_auditor")
_PANEL = "Planner/Auditor (agentic settings)"

AGENTIC = typer.Option(
    "none",
    "--agentic",
    help="planner_auditor: wrap every policy with the Planner/Auditor layer (setting 'llm', or 'llm_no_physics' "
    "with --no-physics-penalty) and write agentic_logs.jsonl.",
    rich_help_panel=_PANEL,
)
PLANNER = typer.Option(
    None, "--planner", help=f"Planner: {' | '.join(PLANNER_KINDS)} (default rule).", rich_help_panel=_PANEL
)
AUDITOR = typer.Option(
    None, "--auditor", help=f"Auditor: {' | '.join(AUDITOR_KINDS)} (default rule).", rich_help_panel=_PANEL
)
LLM_API = typer.Option(
    None,
    "--llm-api",
    help="responses (OpenAI's Responses API) or chat (Chat Completions: vLLM, Ollama, llama.cpp, LM Studio). "
    "Required for an llm planner or auditor; never switched silently.",
    rich_help_panel=_PANEL,
)
LLM_MODEL = typer.Option(
    None, "--llm-model", help="Model name (default: $SOLARCHAIN_LLM_MODEL, then $OPENAI_MODEL).", rich_help_panel=_PANEL
)
LLM_BASE_URL = typer.Option(
    None,
    "--llm-base-url",
    help="OpenAI-compatible endpoint, e.g. http://127.0.0.1:8000/v1 (default: $SOLARCHAIN_LLM_BASE_URL, then "
    "$OPENAI_BASE_URL, then api.openai.com). The key is read from $SOLARCHAIN_LLM_API_KEY or $OPENAI_API_KEY only.",
    rich_help_panel=_PANEL,
)
LLM_TEMPERATURE = typer.Option(
    None, "--llm-temperature", help="Sampling temperature; omitted unless given (reasoning models reject it).", rich_help_panel=_PANEL
)
LLM_TIMEOUT = typer.Option(DEFAULT_TIMEOUT_S, "--llm-timeout", help="Seconds per attempt.", rich_help_panel=_PANEL)
LLM_MAX_RETRIES = typer.Option(
    DEFAULT_MAX_RETRIES, "--llm-max-retries", help="Retries on connection errors, timeouts, 429 and 5xx.", rich_help_panel=_PANEL
)
LLM_MAX_OUTPUT_TOKENS = typer.Option(
    DEFAULT_MAX_OUTPUT_TOKENS, "--llm-max-output-tokens", help="Output-token budget per call (reasoning included).", rich_help_panel=_PANEL
)
LLM_CACHE = typer.Option(
    None, "--llm-cache", help="Directory of the record/replay response cache.", rich_help_panel=_PANEL
)
LLM_CACHE_MODE = typer.Option(
    None,
    "--llm-cache-mode",
    help="off | record (call the endpoint, record new responses) | replay (offline: a miss is an error) | auto "
    "(replay hits, record misses; connects only on a miss). Default: auto with --llm-cache, else off.",
    rich_help_panel=_PANEL,
)


def agentic_options(
    *,
    agentic: str,
    planner: Optional[str],
    auditor: Optional[str],
    llm_api: Optional[str],
    llm_model: Optional[str],
    llm_base_url: Optional[str],
    llm_temperature: Optional[float],
    llm_timeout: float,
    llm_max_retries: int,
    llm_max_output_tokens: int,
    llm_cache: Optional[Path],
    llm_cache_mode: Optional[str],
) -> AgenticOptions | None:
    """Validated options, or None when ``--agentic none``.

    Raises
    ------
    CliError
        Inconsistent flags (e.g. ``--planner`` without ``--agentic planner_auditor``).
    """
    if agentic not in AGENTIC_MODES:
        raise CliError(f"--agentic must be one of {', '.join(AGENTIC_MODES)}, got '{agentic}'")
    if agentic == "none":
        if planner is not None or auditor is not None:
            raise CliError("--planner/--auditor need --agentic planner_auditor")
        return None
    planner = planner or "rule"
    auditor = auditor or "rule"
    uses_llm = "llm" in (planner, auditor)
    mode = llm_cache_mode or ("auto" if llm_cache is not None else "off")
    if mode not in CACHE_MODES:
        raise CliError(f"--llm-cache-mode must be one of {', '.join(CACHE_MODES)}, got '{mode}'")
    if llm_api is not None and llm_api not in LLM_APIS:
        raise CliError(f"--llm-api must be one of {', '.join(LLM_APIS)}, got '{llm_api}'")
    llm = None
    if uses_llm:
        settings = resolve_llm_settings(
            api=llm_api,
            model=llm_model,
            base_url=llm_base_url,
            temperature=llm_temperature,
            timeout_s=llm_timeout,
            max_retries=llm_max_retries,
            max_output_tokens=llm_max_output_tokens,
        )
        if mode != "off" and llm_cache is None:
            raise CliError(f"--llm-cache-mode {mode} needs --llm-cache DIR")
        llm = LLMOptions(settings=settings, cache_dir=llm_cache, cache_mode=mode)
    try:
        return AgenticOptions(planner=planner, auditor=auditor, llm=llm)
    except LLMError as error:
        raise CliError(str(error)) from None


#: The command parameters :func:`agentic_options` takes besides ``agentic``.
OPTION_NAMES = (
    "planner",
    "auditor",
    "llm_api",
    "llm_model",
    "llm_base_url",
    "llm_temperature",
    "llm_timeout",
    "llm_max_retries",
    "llm_max_output_tokens",
    "llm_cache",
    "llm_cache_mode",
)


def options_from(params: dict[str, Any], agentic: str) -> AgenticOptions | None:
    """:func:`agentic_options` from a command's parameters (its ``locals()``)."""
    return agentic_options(agentic=agentic, **{name: params[name] for name in OPTION_NAMES})


def agentic_table(summary: list[dict[str, Any]], title: str) -> Table:
    """Mean agentic metrics per policy and setting (rows without them are skipped)."""
    table = Table(title=title, title_justify="left")
    columns = (
        ("audit rate", "audit_rate"),
        ("revision rate", "revision_rate"),
        ("modification rate", "modification_rate"),
        ("mean action delta", "mean_action_delta"),
        ("hard trigger rate", "hard_trigger_rate"),
        ("LLM retries", "llm_failure_count"),
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
