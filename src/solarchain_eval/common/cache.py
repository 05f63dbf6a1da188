"""The package's cache directory (downloaded weather, built datasets, compiled JAX programs)."""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """``$SOLARCHAIN_CACHE_DIR``, else ``$XDG_CACHE_HOME/solarchain-eval``, else ``~/.cache/solarchain-eval``."""
    explicit = os.environ.get("SOLARCHAIN_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "solarchain-eval"
