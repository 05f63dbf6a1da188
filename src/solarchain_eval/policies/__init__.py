"""Policies: the baselines here; Stable-Baselines3 adapters in :mod:`.sb3`."""

from .base import Policy
from .baselines import BASELINES, MyopicPolicy, RandomPolicy, StaticPolicy, make_baseline

__all__ = ["Policy", "BASELINES", "MyopicPolicy", "RandomPolicy", "StaticPolicy", "make_baseline"]
