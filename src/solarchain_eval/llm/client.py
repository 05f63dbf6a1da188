"""Structured calls to any OpenAI-compatible endpoint, with record/replay.

Uses the official ``openai`` SDK (OpenAI, vLLM, Ollama, llama.cpp server, LM Studio, …) with
an explicitly chosen API (``responses``, ``chat`` with a ``json_schema`` response format, or
``chat-json-object`` with a ``json_object`` format carrying the schema, for llama-cpp-python's
server; never a silent fallback from one to another), an explicit timeout, retry count and output-token budget, and an optional
temperature (omitted unless given: reasoning models reject it). The response format is the
strict JSON schema the SDK derives from the output model. Any failure raises a typed
:class:`~solarchain_eval.llm.errors.LLMError`; the API key is never logged, cached or
shown in an error message, even when the server echoes it (it is removed from the response
body before anything reads or stores it). Each HTTP attempt is bounded in total time by
:class:`~.deadline.DeadlineTransport`. Response bodies are stored as strict JSON: the
non-standard constants ``NaN``/``Infinity`` a server may put in its envelope become ``null``
(see docs/output_safety.md).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypeVar
from urllib.parse import parse_qsl, urlsplit

from pydantic import BaseModel, SecretStr

from ..common.redaction import remove_secret as redact
from ..common.redaction import strip_url as safe_url  # an endpoint as recorded: no user info, query or fragment
from .cache import CACHE_MODES, ResponseCache, request_key
from .envelopes import READERS
from .errors import CallSite, LLMCacheMissError, LLMConfigError, LLMError, LLMSchemaError, LLMTransportError
from .response_format import response_format
from .retry import exchange, total_tokens

T = TypeVar("T", bound=BaseModel)

LLM_APIS = ("responses", "chat", "chat-json-object")
DEFAULT_TIMEOUT_S = 60.0
DEFAULT_MAX_RETRIES = 2
DEFAULT_MAX_OUTPUT_TOKENS = 4096
API_KEY_VARS = ("SOLARCHAIN_LLM_API_KEY", "OPENAI_API_KEY")
BASE_URL_VARS = ("SOLARCHAIN_LLM_BASE_URL", "OPENAI_BASE_URL")
MODEL_VARS = ("SOLARCHAIN_LLM_MODEL", "OPENAI_MODEL")


@dataclass(frozen=True)
class LLMSettings:
    """Endpoint and generation settings (everything except the key is safe to log).

    Attributes
    ----------
    api : {"responses", "chat", "chat-json-object"}
    model : str
    base_url : str or None
        None selects the SDK's default endpoint (api.openai.com).
    api_key : SecretStr or None
        Needed only when a network client is built (never in replay mode).
    temperature : float or None
        Sent only when given.
    timeout_s : float
        Total time of one attempt (connect, send, the whole answer), seconds.
    max_retries : int
        Retries of the SDK on connection errors, timeouts, 408/409/429 and 5xx answers.
    max_output_tokens : int
        Output-token budget per call (reasoning tokens included).
    seed : int or None
        Sampling seed, sent (and part of the cache key) only when given; llama.cpp servers
        honour it.
    decoding : str or None
        How the local model server decodes (:data:`~.local_server.DECODINGS`); set by
        ``--llm-backend local`` only, and then part of the cache key (the two decodings answer
        differently).
    """

    api: str
    model: str
    base_url: str | None = None
    api_key: SecretStr | None = field(default=None, repr=False)
    temperature: float | None = None
    timeout_s: float = DEFAULT_TIMEOUT_S
    max_retries: int = DEFAULT_MAX_RETRIES
    max_output_tokens: int = DEFAULT_MAX_OUTPUT_TOKENS
    seed: int | None = None
    decoding: str | None = None

    def describe(self) -> dict[str, Any]:
        """The settings for run metadata: no key, and no credentials inside the URL."""
        return {
            "api": self.api,
            "model": self.model,
            "base_url": safe_url(self.base_url),
            "temperature": self.temperature,
            "timeout_s": self.timeout_s,
            "max_retries": self.max_retries,
            "max_output_tokens": self.max_output_tokens,
            "seed": self.seed,
            **({"decoding": self.decoding} if self.decoding is not None else {}),
        }


def _first_env(names: tuple[str, ...], environ: Mapping[str, str]) -> str | None:
    for name in names:
        value = environ.get(name, "").strip()
        if value:
            return value
    return None


def resolve_llm_settings(
    *,
    api: str | None,
    model: str | None = None,
    base_url: str | None = None,
    temperature: float | None = None,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    max_retries: int = DEFAULT_MAX_RETRIES,
    max_output_tokens: int = DEFAULT_MAX_OUTPUT_TOKENS,
    environ: Mapping[str, str] | None = None,
    seed: int | None = None,
) -> LLMSettings:
    """Settings from explicit values, else ``SOLARCHAIN_LLM_*``, else ``OPENAI_*`` variables.

    Raises
    ------
    LLMConfigError
        No API chosen, no model, or a value out of range.
    """
    env = os.environ if environ is None else environ
    if api not in LLM_APIS:
        raise LLMConfigError.about(
            "choose the API explicitly with {opt_llm_api} responses (OpenAI's Responses API) or "
            "{opt_llm_api} chat (Chat Completions, what most OpenAI-compatible servers speak) or {opt_llm_api} "
            "chat-json-object (llama-cpp-python's server); got {api!r}",
            api=api,
        )
    model = model or _first_env(MODEL_VARS, env)
    if not model:
        raise LLMConfigError.about("no model: pass {opt_llm_model} or set SOLARCHAIN_LLM_MODEL (or OPENAI_MODEL)")
    if not timeout_s > 0:
        raise LLMConfigError(f"the timeout must be positive, got {timeout_s}")
    if max_retries < 0:
        raise LLMConfigError(f"max retries must be >= 0, got {max_retries}")
    if max_output_tokens < 1:
        raise LLMConfigError(f"the output-token budget must be >= 1, got {max_output_tokens}")
    if temperature is not None and not 0.0 <= temperature <= 2.0:
        raise LLMConfigError(f"temperature must be in [0, 2], got {temperature}")
    key = _first_env(API_KEY_VARS, env)
    return LLMSettings(
        api=api,
        model=model,
        base_url=base_url or _first_env(BASE_URL_VARS, env),
        api_key=SecretStr(key) if key else None,
        temperature=temperature,
        timeout_s=float(timeout_s),
        max_retries=int(max_retries),
        max_output_tokens=int(max_output_tokens),
        seed=None if seed is None else int(seed),
    )


@dataclass(frozen=True)
class LLMReply:
    """A validated structured output and the call's log metadata."""

    output: BaseModel
    meta: dict[str, Any]


def _sdk_retries(error: Any) -> bool:  # an openai.APIStatusError (the SDK is imported lazily)
    """Whether the openai SDK retried this status (its rule: the server's ``x-should-retry`` header,
    else 408, 409, 429 and 5xx), so the message counts the attempts actually made: a 401 is one.
    """
    hint = error.response.headers.get("x-should-retry")
    if hint in ("true", "false"):
        return hint == "true"
    return error.status_code in (408, 409, 429) or error.status_code >= 500


class StructuredLLM:
    """Structured-output calls with an optional record/replay cache.

    Parameters
    ----------
    settings : LLMSettings
    cache_dir : path, optional
        Required unless ``cache_mode`` is ``"off"``.
    cache_mode : {"off", "record", "replay", "auto"}
        See :mod:`solarchain_eval.llm.cache`.
    """

    def __init__(self, settings: LLMSettings, *, cache_dir: Path | str | None = None, cache_mode: str = "off") -> None:
        if cache_mode not in CACHE_MODES:
            raise LLMConfigError(f"unknown cache mode {cache_mode!r} (choose from {', '.join(CACHE_MODES)})")
        if cache_mode != "off" and cache_dir is None:
            raise LLMConfigError.about("{opt_llm_cache_mode} {mode} needs {opt_llm_cache} DIR", mode=cache_mode)
        self.settings = settings
        self.cache_mode = cache_mode
        self.cache = ResponseCache(cache_dir) if cache_mode != "off" and cache_dir is not None else None
        self._client: Any = None
        if cache_mode in ("off", "record"):
            self._client = self._build_client()  # fail fast on missing credentials

    # --- public ---------------------------------------------------------------------------
    def request(
        self, messages: list[dict[str, str]], output_type: type[T], site: CallSite, *, invalid_retries: int = 0
    ) -> LLMReply:
        """One structured call (or cache hit) for ``site``; raises a located LLMError.

        ``invalid_retries`` > 0 asks again, up to that many times, when a reply does not validate
        (:class:`LLMSchemaError`, e.g. a number out of its range): each new attempt is the request
        followed by the rejected reply and a message naming the problem. The cache entry keeps
        the rejected replies with the accepted one, under the request's key, so a replay gives
        the same output, retries and tokens; ``meta["invalid_replies"]`` counts them.
        """
        try:
            return self._request(messages, output_type, site, invalid_retries)
        except LLMError as error:
            raise error.at(site) from None

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def canonical_request(self, messages: list[dict[str, str]], output_type: type[BaseModel]) -> dict[str, Any]:
        s = self.settings
        parameters: dict[str, Any] = {"temperature": s.temperature, "max_output_tokens": s.max_output_tokens}
        if s.seed is not None:  # only when set, so recordings made without a seed keep their keys
            parameters["seed"] = s.seed
        if s.decoding is not None:
            parameters["decoding"] = s.decoding
        return {
            "api": s.api,
            "model": s.model,
            "messages": messages,
            "schema": response_format(output_type, s.api),
            "parameters": parameters,
        }

    # --- internals --------------------------------------------------------------------------
    def _request(
        self, messages: list[dict[str, str]], output_type: type[T], site: CallSite, invalid_retries: int = 0
    ) -> LLMReply:
        request = self.canonical_request(messages, output_type)
        key = request_key(request)
        entry = self.cache.get(key, request) if self.cache is not None else None
        if entry is None:
            if self.cache_mode == "replay":
                raise LLMCacheMissError(f"key {key} is not in {self.cache.root if self.cache else '?'}")
            entry = exchange(self._call, request, self.settings.api, output_type, invalid_retries)  # accepted only
            if self.cache is not None:
                entry = self.cache.put(key, entry)
        output, usage = READERS[self.settings.api](entry["response"], output_type)
        rejected = entry.get("rejected", [])
        meta = {
            "kind": site.kind,
            "cache_key": key,
            "latency_s": entry["latency_s"],
            "input_tokens": total_tokens(usage.input_tokens, [r["usage"]["input_tokens"] for r in rejected]),
            "output_tokens": total_tokens(usage.output_tokens, [r["usage"]["output_tokens"] for r in rejected]),
            "request_id": entry.get("request_id"),
            "model": entry.get("model"),
            "retries": int(entry["retries"]),
        }
        if invalid_retries > 0:  # only for callers that retry, so other logs keep their fields
            meta["invalid_replies"] = len(rejected)
        return LLMReply(output, meta)

    def _secret(self) -> str | None:
        key = self.settings.api_key
        return key.get_secret_value() if key is not None else None

    def _hide(self, text: str) -> str:
        """``text`` without the key or the credentials of the base URL (servers echo them)."""
        for secret in (self._secret(), *_url_secrets(self.settings.base_url)):
            text = redact(text, secret)
        return text

    def _build_client(self) -> Any:
        secret = self._secret()
        if not secret:
            raise LLMConfigError(
                "no API key: set SOLARCHAIN_LLM_API_KEY (or OPENAI_API_KEY); for an endpoint without "
                "authentication any non-empty value will do"
            )
        import openai

        from .deadline import DeadlineTransport

        return openai.OpenAI(
            api_key=secret,
            base_url=self.settings.base_url,
            timeout=self.settings.timeout_s,
            max_retries=self.settings.max_retries,
            http_client=openai.DefaultHttpxClient(transport=DeadlineTransport(self.settings.timeout_s)),
        )

    def _call(self, request: dict[str, Any]) -> dict[str, Any]:
        import openai

        if self._client is None:
            self._client = self._build_client()
        s = self.settings
        params = request["parameters"]
        optional = {} if params["temperature"] is None else {"temperature": params["temperature"]}
        if "seed" in params:
            optional["seed"] = params["seed"]
        started = time.perf_counter()
        try:
            if s.api == "chat-json-object":
                # llama-cpp-python reads max_tokens (not max_completion_tokens) and turns the
                # json_object format's schema into a grammar.
                raw = self._client.chat.completions.with_raw_response.create(
                    model=request["model"],
                    messages=request["messages"],
                    response_format=request["schema"],
                    max_tokens=params["max_output_tokens"],
                    **optional,
                )
            elif s.api == "chat":
                raw = self._client.chat.completions.with_raw_response.create(
                    model=request["model"],
                    messages=request["messages"],
                    response_format=request["schema"],
                    max_completion_tokens=params["max_output_tokens"],
                    **optional,
                )
            else:
                raw = self._client.responses.with_raw_response.create(
                    model=request["model"],
                    input=request["messages"],
                    text={"format": request["schema"]},
                    max_output_tokens=params["max_output_tokens"],
                    **optional,
                )
        except openai.APITimeoutError:
            raise LLMTransportError(
                f"no answer within {s.timeout_s:g} s after {s.max_retries + 1} attempt(s) to "
                f"{safe_url(s.base_url) or 'the default endpoint'}"
            ) from None
        except openai.APIStatusError as error:
            attempts = s.max_retries + 1 if _sdk_retries(error) else 1
            raise LLMTransportError(
                f"HTTP {error.status_code} after {attempts} attempt(s): {self._hide(_short(error.message))}"
            ) from None
        except openai.APIConnectionError as error:
            raise LLMTransportError(
                f"cannot connect to {safe_url(s.base_url) or 'the default endpoint'} after {s.max_retries + 1} "
                f"attempt(s): {self._hide(_short(str(error.__cause__ or error)))}"
            ) from None
        except openai.OpenAIError as error:
            raise LLMTransportError(self._hide(_short(str(error)))) from None
        latency_s = time.perf_counter() - started
        text = raw.http_response.text
        try:
            # NaN/Infinity are not JSON (RFC 8259); stored as null so cache entries stay strict.
            body = _redact_json(json.loads(text, parse_constant=lambda _name: None), self._hide)
        except (json.JSONDecodeError, RecursionError):
            raise LLMSchemaError(f"the response body is not JSON: {self._hide(_short(text))!r}") from None
        return {
            "request": request,
            "response": body,
            "latency_s": round(latency_s, 6),
            "request_id": _redact_json(raw.request_id, self._hide)
            or (body.get("id") if isinstance(body, dict) else None),
            "retries": int(getattr(raw, "retries_taken", 0)),
            "model": body.get("model") if isinstance(body, dict) else None,
            "recorded_at": datetime.now(UTC).isoformat(timespec="seconds"),
        }


def _redact_json(value: Any, hide: Callable[[str], str]) -> Any:
    """``value`` with ``hide`` applied to every string in it (servers may echo the key)."""
    if isinstance(value, str):
        return hide(value)
    if isinstance(value, list):
        return [_redact_json(v, hide) for v in value]
    if isinstance(value, dict):
        return {hide(str(k)): _redact_json(v, hide) for k, v in value.items()}
    return value


def _url_secrets(url: str | None) -> list[str]:
    """The password and query values of ``url`` (4+ characters: shorter ones are not secrets)."""
    if not url:
        return []
    try:
        parts = urlsplit(url)
        values = [parts.password or "", *(v for _, v in parse_qsl(parts.query, keep_blank_values=True))]
    except ValueError:
        return []
    return [v for v in values if len(v) >= 4]


def _short(text: str, limit: int = 300) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[:limit] + "…"
