"""A content-addressed record/replay cache of LLM responses.

The key of a request is the sha256 of its canonical JSON (api, model, messages, response
schema, generation parameters; sorted keys, no whitespace). Neither the endpoint URL nor the
API key is part of it, so a recording replays anywhere. Each entry ``DIR/ab/abcd….json`` holds
the request, the raw response body, usage, latency, request id and retries; it is written once,
atomically (a hard link from a complete temporary file, so a concurrent writer of the same key
can never leave a partial or overwritten file), and never modified.

Modes (``--llm-cache-mode``):

- ``off``: no cache; every request goes to the endpoint.
- ``record``: the endpoint client is built up front; a request already in the cache is served
  from it (entries are immutable), any other goes to the endpoint and is recorded.
- ``auto``: like ``record``, but the client is built only at the first miss, so a complete
  recording replays without credentials or network.
- ``replay``: never builds a client; a miss is a hard error.

Only accepted responses (valid structured output) are recorded: an entry exists only for an
exchange that ended in one. When the caller lets the model answer again after an invalid reply
(:mod:`~solarchain_eval.llm.retry`), the entry also keeps the rejected replies before it
(``rejected``), so a replay reports the same retries and tokens. Entries are strict JSON
(``NaN``/``Infinity`` are refused on write and on read) and never hold the API key: the client
removes it from response bodies before they reach the cache.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from .errors import LLMCacheError

CACHE_MODES = ("off", "record", "replay", "auto")
ENTRY_FORMAT = 1


def canonical_json(payload: Any) -> str:
    """Deterministic JSON text: sorted keys, no whitespace, UTF-8 kept."""
    return json.dumps(payload, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def request_key(request: dict[str, Any]) -> str:
    """sha256 (hex) of the canonical request."""
    return hashlib.sha256(canonical_json(request).encode("utf-8")).hexdigest()


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not strict JSON")


class ResponseCache:
    """Entries under ``root``, one JSON file per request key."""

    def __init__(self, root: Path | str) -> None:
        self.root = Path(root)

    def path(self, key: str) -> Path:
        return self.root / key[:2] / f"{key}.json"

    def get(self, key: str, request: dict[str, Any]) -> dict[str, Any] | None:
        """The entry for ``key`` (checked against ``request``), or None when absent."""
        path = self.path(key)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return None
        except OSError as error:
            raise LLMCacheError(f"cannot read cache entry {path}: {error}") from None
        try:
            entry = json.loads(text, parse_constant=_refuse_constant)
        except (json.JSONDecodeError, ValueError) as error:
            raise LLMCacheError(f"cache entry {path} is not valid JSON ({error}); delete it to re-record") from None
        if not isinstance(entry, dict) or entry.get("format") != ENTRY_FORMAT or entry.get("key") != key:
            raise LLMCacheError(f"cache entry {path} has an unknown format or the wrong key; delete it to re-record")
        if entry.get("request") != json.loads(canonical_json(request)):
            raise LLMCacheError(f"cache entry {path} was recorded for a different request")
        for field in ("response", "latency_s", "retries"):
            if field not in entry:
                raise LLMCacheError(f"cache entry {path} lacks the field '{field}'; delete it to re-record")
        return entry

    def put(self, key: str, entry: dict[str, Any]) -> dict[str, Any]:
        """Write ``entry`` for ``key`` unless one exists; returns the entry now stored."""
        entry = {"format": ENTRY_FORMAT, "key": key, **entry}
        path = self.path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{key[:12]}.", suffix=".partial", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as handle:
                handle.write(json.dumps(entry, indent=1, sort_keys=True, ensure_ascii=False, allow_nan=False) + "\n")
                handle.flush()
                os.fsync(handle.fileno())
            os.chmod(tmp_name, 0o644)
            try:
                os.link(tmp_name, path)  # atomic and never overwrites
            except FileExistsError:
                existing = self.get(key, entry["request"])
                return existing if existing is not None else entry
            except OSError:
                # No hard links on this file system: an atomic rename, unless the entry exists.
                if path.exists():
                    existing = self.get(key, entry["request"])
                    return existing if existing is not None else entry
                os.replace(tmp_name, path)
        finally:
            Path(tmp_name).unlink(missing_ok=True)
        return entry
