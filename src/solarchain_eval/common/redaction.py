"""Removing credentials from what is recorded or shown: command lines, agent specs, run
metadata and error messages (the one home of redaction; see docs/security.md).

Text may carry secrets in four places: URL user info (``https://user:pw@host``), URL query
values (``?token=…``), the value of any option whose name mentions a key, token, secret,
password or credential (``--api-key sk-…``, ``--hf-token=…``), and such a ``NAME=VALUE`` pair
in free text (``--agent-arg api_key=sk-…``). :func:`redact_command`, :func:`redact_text` and
:func:`redact_spec` replace each with ``[redacted]``, as do the values of the API-key
environment variables should they appear verbatim. :func:`redact_metadata` applies them to the
fields of a ``run_metadata.json`` that hold a command or an agent spec. See
docs/output_safety.md.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any
from urllib.parse import urlsplit, urlunsplit

REDACTED = "[redacted]"
#: Words of an option name (split at - and _) that make its value a secret ("tokens" is a count).
_SECRET_WORDS = ("key", "token", "secret", "password", "passwd", "pwd", "credential", "credentials", "auth")
_URL = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*://[^\s'\"<>]+")
#: ``NAME=VALUE`` in free text (not inside a word): the value is a secret when the name says so.
_PAIR = re.compile(r"(?<![A-Za-z0-9_.-])([A-Za-z][A-Za-z0-9_.-]*)=([^\s&,;'\"<>]+)")
#: ``Authorization: Bearer …``-style credentials.
_BEARER = re.compile(r"\b(Bearer|Basic)\s+[A-Za-z0-9._~+/=-]{8,}")
#: Environment variables holding keys whose values never appear in a recorded command.
SECRET_ENV_VARS = ("SOLARCHAIN_LLM_API_KEY", "OPENAI_API_KEY")


def redact_url(url: str) -> str:
    """``url`` with its user info, every query value and the fragment replaced (idempotent)."""
    match = re.match(r"([A-Za-z][A-Za-z0-9+.-]*://)([^/?#]*)(.*)", url, re.DOTALL)
    if match is None:
        return url
    scheme, netloc, rest = match.groups()
    if "@" in netloc:
        netloc = f"{REDACTED}@{netloc.rpartition('@')[2]}"
    rest, hash_, fragment = rest.partition("#")
    path, question, query = rest.partition("?")
    if query:
        query = "&".join(
            f"{k}={_redacted(v)}" if eq else _redacted(k)
            for k, eq, v in (part.partition("=") for part in query.split("&"))
        )
    return f"{scheme}{netloc}{path}{question}{query}{hash_}{_redacted(fragment) if fragment else ''}"


def strip_url(url: str | None) -> str | None:
    """``url`` without user info, query or fragment, as an endpoint is recorded (they may carry
    credentials; unlike :func:`redact_url`, nothing marks where they were)."""
    if not url:
        return url
    parts = urlsplit(url)
    host = parts.hostname or ""
    netloc = f"{host}:{parts.port}" if parts.port else host
    return urlunsplit((parts.scheme, netloc, parts.path, "", ""))


def _redacted(value: str) -> str:
    # A value redacted before keeps what follows it: in a message the URL's match runs on into the
    # text after it ("…?token=[redacted]): cannot connect"), which must survive a second pass.
    return value if value.startswith(REDACTED) else REDACTED


def redact_spec(spec: str) -> str:
    """An agent spec (``NAME=TARGET``) safe to record: a URL target without user info or query values.

    Only URLs are redacted: the spec's own ``NAME=`` is a row name, never a secret.
    """
    return _URL.sub(lambda m: redact_url(m.group(0)), str(spec))


def redact_text(text: str, secrets: Iterable[str | None] = ()) -> str:
    """``text`` with URLs redacted (:func:`redact_url`), ``NAME=VALUE`` pairs whose name mentions
    a key, token, secret or password redacted, bearer credentials and every given secret removed."""
    out = redact_spec(str(text))
    out = _PAIR.sub(lambda m: f"{m.group(1)}={_redacted(m.group(2))}" if _names_secret(m.group(1)) else m.group(0), out)
    out = _BEARER.sub(lambda m: f"{m.group(1)} {REDACTED}", out)
    for secret in [*secrets, *_env_secrets()]:
        if secret:
            out = out.replace(secret, REDACTED)
    return out


def _names_secret(option: str) -> bool:
    words = re.split(r"[-_.]+", option.strip("-").lower())
    return any(w in _SECRET_WORDS or w.endswith(("key", "token", "secret")) for w in words)


def _env_secrets() -> list[str]:
    return [v for v in (os.environ.get(name, "").strip() for name in SECRET_ENV_VARS) if len(v) >= 4]


def redact_command(argv: Sequence[str], secrets: Iterable[str | None] = ()) -> list[str]:
    """``argv`` safe to record: secret option values, URL credentials and known keys replaced."""
    known = [*(s for s in secrets if s), *_env_secrets()]
    out: list[str] = []
    hide_next = False
    for arg in (str(a) for a in argv):
        if hide_next:
            out.append(REDACTED)
            hide_next = False
            continue
        if arg.startswith("-") and not arg.startswith("---"):
            name, eq, _value = arg.partition("=")
            if _names_secret(name):
                if eq:
                    out.append(f"{name}={REDACTED}")
                else:
                    hide_next = True
                    out.append(arg)
                continue
        out.append(redact_text(arg, known))
    return out


def remove_secret(text: str, secret: str | None) -> str:
    """``text`` with every occurrence of ``secret`` (and of its long prefixes) replaced.

    Keys under 4 characters (placeholders such as ``"x"`` for servers that need none) are not
    secrets and are left alone: replacing them would rewrite ordinary words of every reply.
    """
    if not secret or len(secret) < 4:
        return text
    out = text.replace(secret, REDACTED)
    # Servers often echo a shortened key ("sk-abc...xyz"); hide any 8+ character prefix too.
    if len(secret) >= 8:
        for length in range(len(secret) - 1, 7, -1):
            out = out.replace(secret[:length], REDACTED)
    return out


def redact_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """Keyword options (an agent's ``--agent-arg``) safe to record: the value of every option whose
    name mentions a key, token, secret or password replaced, and text values redacted as free text."""
    return {
        key: REDACTED if _names_secret(str(key)) else (redact_text(value) if isinstance(value, str) else value)
        for key, value in options.items()
    }


def redact_metadata(metadata: Mapping[str, Any]) -> dict[str, Any]:
    """A ``run_metadata.json`` object safe to show: its command and agent specs redacted (older
    runs recorded them verbatim; the LLM endpoint is recorded without credentials)."""
    out = dict(metadata)
    if isinstance(out.get("command"), list):
        out["command"] = redact_command(out["command"])
    if isinstance(out.get("policy_specs"), list):
        out["policy_specs"] = [redact_spec(str(s)) for s in out["policy_specs"]]
    return out
