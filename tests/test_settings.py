"""A setting has one definition: rollouts, the evaluate stage, the grid and the report agree on it."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from solarchain_eval.evaluation.records import summarize
from solarchain_eval.evaluation.runner import EvaluationSpec
from solarchain_eval.evaluation.settings import (
    KNOWN_SETTINGS,
    SETTINGS,
    Setting,
    register_setting,
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
        assert s.policies, f"{name} evaluates no policy by default"
        assert GOVERNANCE_LABELS[name] == s.governance_label and setting_label(name) == s.label
        agentic = object() if s.agentic else None
        spec = EvaluationSpec(policies=[], no_physics_penalty=s.no_physics_penalty, agentic=agentic)
        assert spec.setting == name


def test_a_registered_setting_is_seen_by_rollouts_and_the_grid(monkeypatch):
    from solarchain_eval.experiments.grid import GridSpec, plan_units

    monkeypatch.setitem(KNOWN_SETTINGS, "stress", KNOWN_SETTINGS["main"])  # removed again after the test
    register_setting(Setting("stress", True, False, "main", "Stress", "RL stress", ("ppo",)))
    assert not setting_has_physics_penalty("stress")  # the rollouts' view
    units = plan_units(GridSpec.from_preset("paper", settings=("stress",)))
    assert [u.name for u in units if u.kind == "eval"] == [
        f"eval/ppo-stress-{s}" for s in (20260511, 20260512, 20260513)
    ]
    with pytest.raises(ValueError, match="model_setting"):
        register_setting(Setting("odd", False, False, "llm", "Odd", "odd"))


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


def test_a_registered_setting_runs_through_the_grid_under_its_name(monkeypatch, tiny_dataset, tmp_path):
    """A setting added with register_setting is evaluated (its records carry its name), not refused."""
    from solarchain_eval.evaluation.runner import EvaluationSpec as Spec
    from solarchain_eval.experiments.grid import GridSpec
    from solarchain_eval.experiments.paper import run_paper

    monkeypatch.setitem(KNOWN_SETTINGS, "stress", KNOWN_SETTINGS["main"])  # removed again after the test
    register_setting(Setting("stress", True, False, "main", "Stress", "RL stress", ("static",)))
    spec = GridSpec.from_preset(
        "smoke", episodes=2, seeds=(7,), settings=("stress",), policies=("static",), data_dir=tiny_dataset
    )
    outcome = run_paper(spec, tmp_path / "root")
    assert outcome.complete and [u.name for u in outcome.units] == ["eval/static-stress-7"]
    metrics = pd.read_csv(tmp_path / "root" / "combined" / "stress" / "metrics.csv")
    assert set(metrics["setting"]) == {"stress"} and len(metrics) == 2
    with pytest.raises(ValueError, match="no_physics_penalty=True"):
        Spec(policies=["static"], setting_label="stress")  # the stress reward drops the physics penalty
