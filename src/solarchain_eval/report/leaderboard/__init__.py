"""The leaderboard: every policy of one protocol, ranked per setting (docs/comparing_results.md).

:func:`make_leaderboards` reads the inputs (:mod:`.inputs`, tarballs through :mod:`.tarballs`),
ranks them (:mod:`.ranking`) and writes the boards' files (:mod:`.render`, the Pareto figure of
:mod:`.pareto`). It loads its module on first use (PEP 562), so reading a light submodule does
not pull in matplotlib.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...common.lazy import lazy_getattr

#: Public name -> the submodule that defines it.
_EXPORTS = {"LeaderboardOutcome": "make", "make_leaderboards": "make"}

__all__ = ["LeaderboardOutcome", "make_leaderboards"]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ resolves them
    from .make import LeaderboardOutcome, make_leaderboards


__getattr__ = lazy_getattr(__name__, _EXPORTS, globals())
