"""What a run asks of the Planner/Auditor layer, as one options model, and its validation.

:class:`GovernanceRequest` has one field per option (``--agentic``, ``--planner``, ``--llm-api``,
...). Its fields drive the command line too: each field's metadata holds the option's help, and
:func:`solarchain_eval.cli.agentic.governance_options` turns the fields into the options of every
command that evaluates. Adding an option is one field here (plus its use in :meth:`resolve`).
Errors name the fields (``llm_cache_mode``); the command line shows them as flags.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from ..common.errors import NamesOptions, OptionsError
from ..llm.cache import CACHE_MODES
from ..llm.client import (
    DEFAULT_MAX_OUTPUT_TOKENS,
    DEFAULT_MAX_RETRIES,
    DEFAULT_TIMEOUT_S,
    LLM_APIS,
    resolve_llm_settings,
)
from ..llm.errors import LLMError
from ..llm.serving import local_server
from .auditor import AUDITOR_KINDS
from .factory import AgenticOptions, LLMOptions
from .planner import PLANNER_KINDS

AGENTIC_MODES = ("none", "planner_auditor")
LLM_BACKENDS = ("remote", "local")


class GovernanceRequestError(NamesOptions, OptionsError, ValueError):
    """Inconsistent governance options (the message names the fields at fault)."""


def _option(default: Any, help: str, **extra: Any) -> Any:
    return field(default=default, metadata={"help": help, **extra})


@dataclass(frozen=True)
class GovernanceRequest:
    """The Planner/Auditor options of one run, as given (validated by :meth:`resolve`).

    Each field is one command-line option of ``evaluate``, ``paper`` and ``bench-llm`` (the flag
    is the field name with dashes, or the metadata's ``param_decls``); its metadata ``help`` is the
    option's help text.
    """

    agentic: str = _option(
        "none",
        "planner_auditor: wrap every policy with the Planner/Auditor layer (setting 'llm', or 'llm_no_physics' "
        "with --no-physics-penalty) and write agentic_logs.jsonl.",
    )
    llm_backend: str = _option(
        "remote",
        "remote: the endpoint of --llm-base-url. local: start llama-cpp-python's server with --llm-model "
        "(default: the bundled SmolLM2-135M-Instruct; or a GGUF path) on 127.0.0.1 for the run and stop it after; "
        "no key or network needed (needs the llm extra). See docs/llm.md.",
    )
    planner: str | None = _option(None, f"Planner: {' | '.join(PLANNER_KINDS)} (default rule).")
    auditor: str | None = _option(None, f"Auditor: {' | '.join(AUDITOR_KINDS)} (default rule).")
    llm_api: str | None = _option(
        None,
        "responses (OpenAI's Responses API), chat (Chat Completions with a json_schema format: OpenAI, vLLM, "
        "Ollama, llama-server) or chat-json-object (json_object format with the schema: llama-cpp-python's server; "
        "the default with --llm-backend local). Required for a remote llm planner or auditor; never switched silently.",
    )
    llm_model: str | None = _option(
        None,
        "Model name (default: $SOLARCHAIN_LLM_MODEL, then $OPENAI_MODEL); with --llm-backend local a GGUF path "
        "(default: the bundled model).",
    )
    llm_base_url: str | None = _option(
        None,
        "OpenAI-compatible endpoint, e.g. http://127.0.0.1:8000/v1 (default: $SOLARCHAIN_LLM_BASE_URL, then "
        "$OPENAI_BASE_URL, then api.openai.com). The key is read from $SOLARCHAIN_LLM_API_KEY or $OPENAI_API_KEY only.",
    )
    llm_temperature: float | None = _option(
        None, "Sampling temperature; omitted unless given (reasoning models reject it)."
    )
    llm_timeout: float = _option(DEFAULT_TIMEOUT_S, "Seconds per attempt.")
    llm_max_retries: int = _option(DEFAULT_MAX_RETRIES, "Retries on connection errors, timeouts, 429 and 5xx.")
    llm_max_output_tokens: int = _option(
        DEFAULT_MAX_OUTPUT_TOKENS, "Output-token budget per call (reasoning included)."
    )
    llm_threads: int | None = _option(
        None,
        "With --llm-backend local: CPU threads of the model server (default: the CPUs available, at most 2; the "
        "same replies either way). Use 1 on a machine busy with other work (docs/llm.md#speed).",
    )
    llm_decoding: str | None = _option(
        None,
        "With --llm-backend local: jump-forward (default: the schema's fixed text is added in batches, the model "
        "runs only inside values) or grammar (llama-cpp-python samples every token under its JSON grammar; slower, "
        "other answers). Part of the cache key (docs/llm.md#speed).",
    )
    llm_cache: Path | None = _option(None, "Directory of the record/replay response cache.")
    llm_cache_mode: str | None = _option(
        None,
        "off | record (call the endpoint, record new responses) | replay (offline: a miss is an error) | auto "
        "(replay hits, record misses; connects only on a miss). Default: auto with --llm-cache, else off.",
    )

    diagnostics: bool | None = _option(
        None,
        "With --agentic planner_auditor (default on): also write governance_diagnostics.csv, the counterfactual "
        "outcome (V, A, cost, reward, matched energy, slippage) of the proposal, the bounded action and the final action "
        "at every governed step, from the same state and price shock (the executed trajectory is unchanged; "
        "docs/governance.md).",
        param_decls=("--diagnostics/--no-diagnostics",),
    )

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    def resolve(self) -> AgenticOptions | None:
        """Validated :class:`AgenticOptions`, or None when ``agentic`` is ``"none"``.

        Raises
        ------
        GovernanceRequestError
            Inconsistent options (e.g. a planner without ``agentic="planner_auditor"``).
        LLMError
            LLM settings that cannot be resolved (no model, no API, ...).
        """
        if self.agentic not in AGENTIC_MODES:
            raise GovernanceRequestError.about(
                "{opt_agentic} must be one of {modes}, got '{got}'", modes=", ".join(AGENTIC_MODES), got=self.agentic
            )
        if self.agentic == "none":
            if self.planner is not None or self.auditor is not None:
                raise GovernanceRequestError.about("{opt_planner}/{opt_auditor} need {opt_agentic} planner_auditor")
            if self.diagnostics is not None:
                raise GovernanceRequestError.about("{opt_diagnostics} (on or off) needs {opt_agentic} planner_auditor")
            return None
        planner, auditor = self.planner or "rule", self.auditor or "rule"
        for name, kind, kinds in (("planner", planner, PLANNER_KINDS), ("auditor", auditor, AUDITOR_KINDS)):
            if kind not in kinds:  # an option error, before any LLM setting is looked at
                raise GovernanceRequestError.about(
                    f"{{opt_{name}}}: unknown {name} '{{got}}' (choose from {{kinds}})",
                    got=kind,
                    kinds=", ".join(kinds),
                )
        self._check_llm_fields()
        llm = self.llm_options() if "llm" in (planner, auditor) else None
        return AgenticOptions(planner=planner, auditor=auditor, llm=llm, diagnostics=self.diagnostics is not False)

    def llm_options(self) -> LLMOptions:
        """The endpoint settings and cache of the ``--llm-*`` options, whatever ``agentic`` says:
        those of an LLM planner or auditor, and of the LLM agent (``--policies llm-agent``).

        With ``llm_backend="local"`` every call on one request names the same port, so the
        Planner/Auditor and the agent share the one server :meth:`server_spec` starts.

        Raises
        ------
        GovernanceRequestError
            Inconsistent options (e.g. ``--llm-threads`` with the remote backend).
        LLMError
            LLM settings that cannot be resolved (no model, no API, ...).
        """
        self._check_llm_fields()
        mode = self.cache_mode
        settings = self._local_settings() if self.llm_backend == "local" else self._remote_settings()
        if mode != "off" and self.llm_cache is None:
            raise GovernanceRequestError.about("{opt_llm_cache_mode} {mode} needs {opt_llm_cache} DIR", mode=mode)
        return LLMOptions(settings=settings, cache_dir=self.llm_cache, cache_mode=mode)

    def _check_llm_fields(self) -> None:
        mode = self.cache_mode
        if mode not in CACHE_MODES:
            raise GovernanceRequestError.about(
                "{opt_llm_cache_mode} must be one of {modes}, got '{got}'", modes=", ".join(CACHE_MODES), got=mode
            )
        if self.llm_api is not None and self.llm_api not in LLM_APIS:
            raise GovernanceRequestError.about(
                "{opt_llm_api} must be one of {apis}, got '{got}'", apis=", ".join(LLM_APIS), got=self.llm_api
            )
        if self.llm_backend not in LLM_BACKENDS:
            raise GovernanceRequestError.about(
                "{opt_llm_backend} must be one of {backends}, got '{got}'",
                backends=", ".join(LLM_BACKENDS),
                got=self.llm_backend,
            )
        if self.llm_threads is not None:
            if self.llm_threads < 1:
                raise GovernanceRequestError.about("{opt_llm_threads} must be >= 1, got {got}", got=self.llm_threads)
            if self.llm_backend != "local":
                raise GovernanceRequestError.about("{opt_llm_threads} is for {opt_llm_backend} local")
        if self.llm_decoding is not None:
            if self.llm_decoding not in local_server.DECODINGS:
                raise GovernanceRequestError.about(
                    "{opt_llm_decoding} must be one of {choices}, got '{got}'",
                    choices=", ".join(local_server.DECODINGS),
                    got=self.llm_decoding,
                )
            if self.llm_backend != "local":
                raise GovernanceRequestError.about("{opt_llm_decoding} is for {opt_llm_backend} local")

    @functools.cached_property
    def _local_port(self) -> int:
        """The local server's port, chosen once per request (every settings object names it)."""
        return local_server.free_port()

    @property
    def cache_mode(self) -> str:
        """``llm_cache_mode``, defaulting to ``auto`` with a cache directory and ``off`` without."""
        return self.llm_cache_mode or ("auto" if self.llm_cache is not None else "off")

    def _remote_settings(self):
        return resolve_llm_settings(
            api=self.llm_api,
            model=self.llm_model,
            base_url=self.llm_base_url,
            temperature=self.llm_temperature,
            timeout_s=self.llm_timeout,
            max_retries=self.llm_max_retries,
            max_output_tokens=self.llm_max_output_tokens,
        )

    def _local_settings(self):
        """Settings for a server we start: its API, the model's name, temperature 0 and a fixed seed."""
        if self.llm_base_url is not None:
            raise GovernanceRequestError.about(
                "{opt_llm_base_url} is for {opt_llm_backend} remote; the local backend starts its own server"
            )
        api = self.llm_api or local_server.LOCAL_API
        if api != local_server.LOCAL_API:
            raise GovernanceRequestError.about(
                "{opt_llm_backend} local serves with llama-cpp-python, which needs {opt_llm_api} {api}",
                api=local_server.LOCAL_API,
            )
        name, _ = local_server.resolve_model(self.llm_model)
        port = self._local_port
        tokens = self.llm_max_output_tokens
        settings = resolve_llm_settings(
            api=api,
            model=name,
            base_url=f"http://127.0.0.1:{port}/v1",
            temperature=local_server.LOCAL_TEMPERATURE if self.llm_temperature is None else self.llm_temperature,
            timeout_s=self.llm_timeout,
            max_retries=self.llm_max_retries,
            max_output_tokens=local_server.LOCAL_MAX_OUTPUT_TOKENS if tokens == DEFAULT_MAX_OUTPUT_TOKENS else tokens,
            environ={"SOLARCHAIN_LLM_API_KEY": "none"},  # the local server takes no key
            seed=local_server.LOCAL_SEED,
        )
        return replace(settings, decoding=self.llm_decoding or local_server.DEFAULT_DECODING)

    def server_spec(
        self, options: AgenticOptions | None, *, parallel: int = 1, needs_llm: bool = False
    ) -> local_server.ServerSpec | None:
        """The local model server this request needs (None: remote backend, no LLM component, or a
        pure replay, which needs no server), taking ``parallel`` requests at once (one per episode
        in flight) so that concurrent requests never interrupt each other. ``needs_llm``: a policy
        (the LLM agent) calls the model even without an LLM planner or auditor."""
        llm = options.llm if options is not None and options.llm is not None else None
        if llm is None and needs_llm:
            llm = self.llm_options()
        if self.llm_backend != "local" or llm is None or llm.cache_mode == "replay":
            return None
        settings = llm.settings
        _, path = local_server.resolve_model(self.llm_model)
        if path is None:
            local_server.default_model_path()  # raises with the install hint
        port = int(str(settings.base_url).rsplit(":", 1)[1].split("/", 1)[0])
        threads = local_server.default_threads() if self.llm_threads is None else self.llm_threads
        return local_server.ServerSpec(
            model_path=path,
            model_name=settings.model,
            port=port,
            parallel=parallel,
            threads=threads,
            decoding=settings.decoding or local_server.DEFAULT_DECODING,
            requantize=local_server.file_type_for(self.llm_model),
        )


__all__ = ["AGENTIC_MODES", "LLM_BACKENDS", "GovernanceRequest", "GovernanceRequestError", "LLMError"]
