"""The leaderboard: every policy of one protocol, ranked per setting (docs/comparing_results.md).

:func:`make_leaderboards` reads the inputs (:mod:`.inputs`, tarballs through :mod:`.tarballs`),
ranks them (:mod:`.ranking`) and writes the boards' files (:mod:`.render`, the Pareto figure of
:mod:`.pareto`). It loads its module on first use (PEP 562), so reading a light submodule does
not pull in matplotlib.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

#: Public name -> the submodule that defines it.
_EXPORTS = {"LeaderboardOutcome": "make", "make_leaderboards": "make"}

__all__ = ["LeaderboardOutcome", "make_leaderboards"]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ resolves them
    from .make import LeaderboardOutcome, make_leaderboards


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value  # resolved once
    return value
