"""Removing credentials from command lines before they are recorded or shown.

A command line may carry secrets in three places: URL user info (``https://user:pw@host``),
URL query values (``?token=…``) and the value of any option whose name mentions a key, token,
secret, password or credential (``--api-key sk-…``, ``--hf-token=…``). :func:`redact_command`
replaces each with ``[redacted]``, as do the values of the API-key environment variables should
they appear verbatim. See docs/output_safety.md.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence

REDACTED = "[redacted]"
#: Words of an option name (split at - and _) that make its value a secret ("tokens" is a count).
_SECRET_WORDS = ("key", "token", "secret", "password", "passwd", "pwd", "credential", "credentials", "auth")
_URL = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*://[^\s'\"<>]+")
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
            f"{k}={REDACTED}" if eq else REDACTED for k, eq, _ in (part.partition("=") for part in query.split("&"))
        )
    return f"{scheme}{netloc}{path}{question}{query}{hash_}{REDACTED if fragment else ''}"


def redact_text(text: str, secrets: Iterable[str | None] = ()) -> str:
    """``text`` with URLs redacted (:func:`redact_url`) and every given secret removed."""
    out = _URL.sub(lambda m: redact_url(m.group(0)), text)
    for secret in secrets:
        if secret:
            out = out.replace(secret, REDACTED)
    return out


def _names_secret(option: str) -> bool:
    words = re.split(r"[-_]+", option.strip("-").lower())
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
