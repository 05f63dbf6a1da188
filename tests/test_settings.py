"""A setting has one definition: rollouts, the evaluate stage, the grid and the report agree on it."""

from __future__ import annotations

import math

import pandas as pd

from solarchain_eval.experiments.evaluate import EvaluationSpec
from solarchain_eval.experiments.grid import SETTING_REGISTRY, GridSetting, register_setting
from solarchain_eval.experiments.records import summarize
from solarchain_eval.experiments.settings import (
    KNOWN_SETTINGS,
    SETTINGS,
    setting_has_physics_penalty,
    setting_is_agentic,
    setting_name,
)
from solarchain_eval.report.naming import GOVERNANCE_LABELS, setting_label
from solarchain_eval.report.statistics import mean_std


def test_every_view_of_a_setting_agrees():
    for name in SETTINGS:
        s = KNOWN_SETTINGS[name]
        assert setting_name(agentic=s.agentic, no_physics_penalty=s.no_physics_penalty) == name
        assert setting_has_physics_penalty(name) is not s.no_physics_penalty
        assert setting_is_agentic(name) is s.agentic
        grid = SETTING_REGISTRY[name]
        assert (grid.no_physics_penalty, grid.agentic, grid.model_setting) == (
            s.no_physics_penalty,
            s.agentic,
            s.model_setting,
        )
        assert GOVERNANCE_LABELS[name] == s.governance_label and setting_label(name) == s.label
        agentic = object() if s.agentic else None
        spec = EvaluationSpec(policies=[], no_physics_penalty=s.no_physics_penalty, agentic=agentic)
        assert spec.setting == name


def test_a_grid_setting_registers_its_definition(monkeypatch):
    from solarchain_eval.experiments import grid, settings

    known = dict(KNOWN_SETTINGS)
    monkeypatch.setattr(settings, "KNOWN_SETTINGS", known)
    monkeypatch.setattr(grid, "KNOWN_SETTINGS", known)
    monkeypatch.setattr(grid, "SETTING_REGISTRY", dict(SETTING_REGISTRY))
    register_setting(GridSetting("stress", True, ("ppo",), "main"))
    assert grid.SETTING_REGISTRY["stress"].no_physics_penalty
    assert known["stress"].no_physics_penalty and not setting_has_physics_penalty("stress")  # the rollouts' view
    assert "stress" not in KNOWN_SETTINGS


def test_single_episode_std_is_undefined_in_records_and_report():
    """n = 1: the sample std is undefined, null in summary.json and NaN in the report, never 0."""
    frame = pd.DataFrame(
        [{"policy": "static", "setting": "main", "run_seed": 1, "episode": 0, "episode_seed": 1, "start_hour": 0}]
    ).assign(cumulative_reward=-1.5, mean_slippage=0.2)
    (entry,) = summarize(frame)
    assert entry["metrics"]["cumulative_reward"] == {"mean": -1.5, "std": None, "min": -1.5, "max": -1.5}
    mean, std = mean_std([-1.5])
    assert mean == -1.5 and math.isnan(std)
    (two,) = summarize(pd.concat([frame, frame.assign(episode=1, cumulative_reward=-2.5)]))
    assert two["metrics"]["cumulative_reward"]["std"] == pd.Series([-1.5, -2.5]).std(ddof=1)
