"""Command-line options of the Planner/Auditor layer, shared by the commands that evaluate.

The options are module-level ``typer.Option`` objects so every command declares them the same
way; :func:`agentic_options` turns their values into
:class:`~solarchain_eval.agentic.AgenticOptions` (or None without ``--agentic``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer
from rich.table import Table

from ..agentic import AgenticOptions, LLMError, LLMOptions, local_server, resolve_llm_settings
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
LLM_BACKEND_CHOICES = ("remote", "local")
LLM_BACKEND = typer.Option(
    "remote",
    "--llm-backend",
    help="remote: the endpoint of --llm-base-url. local: start llama-cpp-python's server with --llm-model "
    "(default: the bundled SmolLM2-135M-Instruct; or a GGUF path) on 127.0.0.1 for the run and stop it after; "
    "no key or network needed (needs solarchain-eval\\[llm]). See docs/llm.md.",
    rich_help_panel=_PANEL,
)
LLM_API = typer.Option(
    None,
    "--llm-api",
    help="responses (OpenAI's Responses API), chat (Chat Completions with a json_schema format: OpenAI, vLLM, "
    "Ollama, llama-server) or chat-json-object (json_object format with the schema: llama-cpp-python's server; "
    "the default with --llm-backend local). Required for a remote llm planner or auditor; never switched silently.",
    rich_help_panel=_PANEL,
)
LLM_MODEL = typer.Option(
    None,
    "--llm-model",
    help="Model name (default: $SOLARCHAIN_LLM_MODEL, then $OPENAI_MODEL); with --llm-backend local a GGUF path "
    "(default: the bundled model).",
    rich_help_panel=_PANEL,
)
LLM_BASE_URL = typer.Option(
    None,
    "--llm-base-url",
    help="OpenAI-compatible endpoint, e.g. http://127.0.0.1:8000/v1 (default: $SOLARCHAIN_LLM_BASE_URL, then "
    "$OPENAI_BASE_URL, then api.openai.com). The key is read from $SOLARCHAIN_LLM_API_KEY or $OPENAI_API_KEY only.",
    rich_help_panel=_PANEL,
)
LLM_TEMPERATURE = typer.Option(
    None,
    "--llm-temperature",
    help="Sampling temperature; omitted unless given (reasoning models reject it).",
    rich_help_panel=_PANEL,
)
LLM_TIMEOUT = typer.Option(DEFAULT_TIMEOUT_S, "--llm-timeout", help="Seconds per attempt.", rich_help_panel=_PANEL)
LLM_MAX_RETRIES = typer.Option(
    DEFAULT_MAX_RETRIES,
    "--llm-max-retries",
    help="Retries on connection errors, timeouts, 429 and 5xx.",
    rich_help_panel=_PANEL,
)
LLM_MAX_OUTPUT_TOKENS = typer.Option(
    DEFAULT_MAX_OUTPUT_TOKENS,
    "--llm-max-output-tokens",
    help="Output-token budget per call (reasoning included).",
    rich_help_panel=_PANEL,
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

LLM_CONCURRENCY = typer.Option(
    1,
    "--llm-concurrency",
    min=1,
    help="Episodes in flight (threads) while waiting for the model, for servers that answer requests in parallel "
    "(vLLM, OpenAI, llama-server -np N). The files are the same as with 1 when replies are deterministic "
    "(temperature 0 and a seed, or a replayed cache). With --llm-backend local the server accepts N requests "
    "without interrupting one (it answers them one at a time).",
    rich_help_panel=_PANEL,
)


def agentic_options(
    *,
    agentic: str,
    llm_backend: str = "remote",
    planner: str | None,
    auditor: str | None,
    llm_api: str | None,
    llm_model: str | None,
    llm_base_url: str | None,
    llm_temperature: float | None,
    llm_timeout: float,
    llm_max_retries: int,
    llm_max_output_tokens: int,
    llm_cache: Path | None,
    llm_cache_mode: str | None,
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
    if llm_backend not in LLM_BACKEND_CHOICES:
        raise CliError(f"--llm-backend must be one of {', '.join(LLM_BACKEND_CHOICES)}, got '{llm_backend}'")
    llm = None
    if uses_llm and llm_backend == "local":
        settings = _local_settings(
            llm_api, llm_model, llm_base_url, llm_temperature, llm_timeout, llm_max_retries, llm_max_output_tokens
        )
        if mode != "off" and llm_cache is None:
            raise CliError(f"--llm-cache-mode {mode} needs --llm-cache DIR")
        llm = LLMOptions(settings=settings, cache_dir=llm_cache, cache_mode=mode)
    elif uses_llm:
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


def _local_settings(api, model, base_url, temperature, timeout_s, max_retries, max_output_tokens):
    """Settings for a server we start: its API, the model's name, temperature 0 and a fixed seed."""
    if base_url is not None:
        raise CliError("--llm-base-url is for --llm-backend remote; the local backend starts its own server")
    api = api or local_server.LOCAL_API
    if api != local_server.LOCAL_API:
        raise CliError(
            f"--llm-backend local serves with llama-cpp-python, which needs --llm-api {local_server.LOCAL_API}"
        )
    name, _ = local_server.resolve_model(model)
    port = local_server.free_port()
    return resolve_llm_settings(
        api=api,
        model=name,
        base_url=f"http://127.0.0.1:{port}/v1",
        temperature=local_server.LOCAL_TEMPERATURE if temperature is None else temperature,
        timeout_s=timeout_s,
        max_retries=max_retries,
        max_output_tokens=local_server.LOCAL_MAX_OUTPUT_TOKENS
        if max_output_tokens == DEFAULT_MAX_OUTPUT_TOKENS
        else max_output_tokens,
        environ={"SOLARCHAIN_LLM_API_KEY": "none"},  # the local server takes no key
        seed=local_server.LOCAL_SEED,
    )


def local_server_spec(params: dict[str, Any], options: AgenticOptions | None) -> local_server.ServerSpec | None:
    """The server to start for a command's parameters and options (None: remote backend, no
    LLM component, or a pure replay, which needs no server)."""
    if params["llm_backend"] != "local" or options is None or options.llm is None or options.llm.cache_mode == "replay":
        return None
    settings = options.llm.settings
    _, path = local_server.resolve_model(params["llm_model"])
    if path is None:
        local_server.default_model_path()  # raises with the install hint
    port = int(str(settings.base_url).rsplit(":", 1)[1].split("/", 1)[0])
    parallel = int(params.get("llm_concurrency") or 1)  # concurrent requests must not interrupt each other
    return local_server.ServerSpec(model_path=path, model_name=settings.model, port=port, parallel=parallel)


#: The command parameters :func:`agentic_options` takes besides ``agentic``.
OPTION_NAMES = (
    "llm_backend",
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


def serving(params: dict[str, Any], options: AgenticOptions | None):
    """Context manager: the local model server the command needs, running (or nothing)."""
    import tempfile

    spec = local_server_spec(params, options)
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
