"""Policies: the baselines here; Stable-Baselines3 adapters in :mod:`.sb3`."""

from ..market.baselines import BASELINES, MyopicPolicy, RandomPolicy, StaticPolicy, make_baseline
from .base import Policy

__all__ = ["Policy", "BASELINES", "MyopicPolicy", "RandomPolicy", "StaticPolicy", "make_baseline"]
