"""Agents: every kind built from one request (:mod:`.request`, :mod:`.build`); Stable-Baselines3 adapters in :mod:`.sb3`.

The baselines are the task's (:func:`~.named.baselines`). The solar market's baseline classes stay
importable from here as before (``from solarchain_eval.agents import make_baseline``), resolved from
the market on first use, so that ``import solarchain_eval.agents`` loads no market module.
"""

import importlib
from typing import Any

from .base import Policy

#: Names kept importable from this package, and the module that defines them.
_MARKET_EXPORTS = ("BASELINES", "MyopicPolicy", "RandomPolicy", "StaticPolicy", "make_baseline")
_MARKET_MODULE = "solarchain_eval.market.baselines"


def __getattr__(name: str) -> Any:
    if name not in _MARKET_EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_MARKET_MODULE), name)
    globals()[name] = value  # resolved once
    return value


__all__ = ["Policy", "BASELINES", "MyopicPolicy", "RandomPolicy", "StaticPolicy", "make_baseline"]
