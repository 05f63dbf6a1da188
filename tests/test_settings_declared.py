"""A setting is one object: declared in Python, a settings file or a plugin, with its reward switch,
governance, config overrides and the contrasts the report draws; every way of naming one agrees."""

from __future__ import annotations

import json
from importlib.metadata import EntryPoint

import pandas as pd
import pytest
from typer.testing import CliRunner

import solarchain_eval
from solarchain_eval.cli import app
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.evaluation import settings as settings_module
from solarchain_eval.evaluation.runner import EvaluationSpec
from solarchain_eval.evaluation.settings import (
    KNOWN_SETTINGS,
    SETTINGS,
    Contrast,
    Setting,
    SettingError,
    register_setting,
    setting_pairs,
)
from solarchain_eval.evaluation.settings_file import load_settings
from solarchain_eval.governance.factory import AgenticOptions
from solarchain_eval.report import naming

#: A setting the ``solarchain_eval.settings`` entry point of the plugin test points at.
PLUGIN_SETTING = Setting(
    "plugged", False, True, "main", "Plugged", "RL+oracle", ("ppo",), governance=AgenticOptions(auditor="oracle")
)


@pytest.fixture
def forget():
    """Settings a test registers, removed afterwards (the registry is the process's)."""
    names: list[str] = []
    yield names
    for name in names:
        dict.pop(KNOWN_SETTINGS, name, None)


def test_the_papers_settings_round_trip_through_every_spelling():
    old_runner_config = BenchmarkConfig()
    for name in SETTINGS:
        s = KNOWN_SETTINGS[name]
        agentic = AgenticOptions() if s.agentic else None
        by_fields = EvaluationSpec(policies=[], no_physics_penalty=s.no_physics_penalty, agentic=agentic)
        by_name = EvaluationSpec(policies=[], setting=name)
        by_object = EvaluationSpec(policies=[], setting=s)
        by_label = EvaluationSpec(
            policies=[], setting_label=name, no_physics_penalty=s.no_physics_penalty, agentic=agentic
        )
        for spec in (by_fields, by_name, by_object, by_label):
            assert (spec.setting, spec.no_physics_penalty, spec.agentic is not None) == (
                name,
                s.no_physics_penalty,
                s.agentic,
            )
            assert spec.setting_spec is s
            # the runner's config as before: the default config with the setting's reward switch
            before = old_runner_config.with_updates(no_physics_penalty=s.no_physics_penalty)
            assert spec.run_config().model_dump() == before.model_dump()
    # the governed counterpart: main and no_physics with agentic options are llm and llm_no_physics
    assert EvaluationSpec(policies=[], setting="main", agentic=True).setting == "llm"
    assert EvaluationSpec(policies=[], setting="no_physics", agentic=AgenticOptions()).setting == "llm_no_physics"


def test_the_reports_pairs_are_the_declared_ones_and_equal_the_old_table():
    # The tables report/naming.py wrote out by hand before the pairs were declared by the settings.
    assert naming.AGENTIC_BASE == {"llm": "main", "llm_no_physics": "no_physics"}
    assert naming.ABLATION_PAIRS == {"main": "no_physics", "llm": "llm_no_physics"}
    assert naming.GOVERNANCE_ORDER == ("main", "llm", "no_physics", "llm_no_physics")
    assert naming.AGENTIC_REWARD_LABELS == {"llm": "Main", "llm_no_physics": "No-physics"}
    assert list(naming.AGENTIC_BASE) == ["llm", "llm_no_physics"] and list(naming.ABLATION_PAIRS) == ["main", "llm"]
    assert [(b, t, c.kind) for b, t, c in setting_pairs(names=SETTINGS)] == [
        ("main", "no_physics", "ablation"),
        ("main", "llm", "governance"),
        ("no_physics", "llm_no_physics", "governance"),
        ("llm", "llm_no_physics", "ablation"),
    ]


def test_a_setting_with_a_config_override_runs_under_its_name_and_config(tiny_dataset, tmp_path, forget):
    heavy = Setting(
        "heavy",
        False,
        False,
        "main",
        "Heavy physics",
        "RL heavy",
        ("static",),
        config_overrides={"reward": {"physics_penalty": 7.5}, "market.static_burn_rate": 0.05},
        compare_with=(Contrast("main", "physics_weight", "λp 7.5 instead of 2"),),
    )
    forget.append("heavy")
    register_setting(heavy)
    assert heavy.config_overrides == {"reward.physics_penalty": 7.5, "market.static_burn_rate": 0.05}
    assert setting_pairs("physics_weight") == [("main", "heavy", heavy.compare_with[0])]
    assert naming.setting_label("heavy") == "Heavy physics"
    runs = {}
    for name in ("main", "heavy"):
        runs[name] = solarchain_eval.evaluate(
            "static", data=tiny_dataset, seeds=[7], episodes=1, setting=name, out=tmp_path / name
        )
    metadata = json.loads((tmp_path / "heavy" / "run_metadata.json").read_text())
    assert metadata["setting"] == "heavy" and set(pd.read_csv(tmp_path / "heavy" / "metrics.csv")["setting"]) == {
        "heavy"
    }
    assert metadata["config"]["reward"]["physics_penalty"] == 7.5
    assert metadata["config"]["market"]["static_burn_rate"] == 0.05
    assert runs["heavy"].protocol["config_sha256"] != runs["main"].protocol["config_sha256"]
    assert runs["heavy"].protocol_id != runs["main"].protocol_id
    # the static policy acts with the overridden market config: its burn rate is the setting's
    actions = pd.read_csv(tmp_path / "heavy" / "actions.csv")
    assert actions["burn_rate"].iloc[0] == pytest.approx(0.05)
    # the same object, unregistered, through evaluate(): the same name and config
    dict.pop(KNOWN_SETTINGS, "heavy")
    again = solarchain_eval.evaluate("static", data=tiny_dataset, seeds=[7], episodes=1, setting=heavy)
    assert again.protocol_id == runs["heavy"].protocol_id and set(again.metrics["setting"]) == {"heavy"}


def test_options_that_disagree_with_the_setting_are_one_error():
    with pytest.raises(
        SettingError, match=r"^setting 'no_physics' has no_physics_penalty=True; the evaluation asks for False$"
    ):
        EvaluationSpec(policies=[], setting="no_physics", no_physics_penalty=False)
    with pytest.raises(SettingError, match="'main' and setting_label 'llm' name different settings"):
        EvaluationSpec(policies=[], setting="main", setting_label="llm")
    with pytest.raises(SettingError, match=r"^unknown setting 'nope' \(registered: main, no_physics, llm"):
        solarchain_eval.evaluate("static", setting="nope")
    # the older spelling keeps its own check: a label's reward must equal no_physics_penalty
    with pytest.raises(ValueError, match="has no_physics_penalty=True and agentic=False"):
        EvaluationSpec(policies=[], setting_label="no_physics")


def test_bad_declarations_fail_with_one_line_naming_the_field(forget):
    def one_line(error: pytest.ExceptionInfo) -> str:
        message = str(error.value)
        assert "\n" not in message
        return message

    with pytest.raises(SettingError) as error:
        Setting("x", False, False, "main", "X", "X", config_overrides={"reward.physics_penalt": 1.0})
    assert one_line(error) == "setting 'x': config override reward.physics_penalt: not a field of the benchmark config"
    with pytest.raises(SettingError) as error:
        Setting("x", False, False, "main", "X", "X", config_overrides={"reward": {"physics_penalty": -1}})
    assert one_line(error).startswith("setting 'x': config override reward.physics_penalty: Input should be greater")
    with pytest.raises(SettingError, match="no_physics_penalty: set the setting's no_physics_penalty instead"):
        Setting("x", False, False, "main", "X", "X", config_overrides={"no_physics_penalty": True})
    with pytest.raises(SettingError) as error:
        register_setting(Setting("x", False, False, "main", "X", "X", compare_with=(Contrast("mian", "ablation"),)))
    assert one_line(error).startswith("setting 'x': compare_with: unknown setting 'mian' (registered: main,")
    with pytest.raises(SettingError, match="an ablation contrast pairs a no-physics setting"):
        register_setting(Setting("x", False, False, "main", "X", "X", compare_with=(Contrast("main", "ablation"),)))
    with pytest.raises(SettingError, match="governance needs agentic=True"):
        Setting("x", False, False, "main", "X", "X", governance=AgenticOptions())
    assert "x" not in KNOWN_SETTINGS


def test_a_settings_file_declares_settings_the_command_line_evaluates(tiny_dataset, tmp_path, forget):
    path = tmp_path / "settings.yaml"
    path.write_text(
        "settings:\n"
        "  heavy_file:\n"
        "    label: Heavy\n"
        "    config:\n"
        "      reward.physics_penalty: 5.0\n"
        "    compare_with:\n"
        "      - {base: main, kind: physics_weight, meaning: five instead of two}\n"
        "  heavy_oracle:\n"
        "    governance: {auditor: oracle}\n"
        "    config: {reward: {physics_penalty: 5.0}}\n"
        "    compare_with:\n"
        "      - {base: heavy_file, kind: governance}\n"
    )
    forget.extend(["heavy_file", "heavy_oracle"])
    heavy, oracle = load_settings(path)
    assert KNOWN_SETTINGS["heavy_file"] is heavy and heavy.label == heavy.governance_label == "Heavy"
    assert (oracle.agentic, oracle.governance.auditor, oracle.model_setting) == (True, "oracle", "main")
    assert oracle.policies == ("ppo", "sac", "dqn") and "static" in heavy.policies
    # the governed counterpart comes from the declarations: heavy_file with agentic options is heavy_oracle
    assert EvaluationSpec(policies=[], setting="heavy_file", agentic=True).setting == "heavy_oracle"
    spec = EvaluationSpec(policies=[], setting="heavy_oracle")
    assert spec.agentic.auditor == "oracle" and spec.run_config().reward.physics_penalty == 5.0

    forget_cli = dict.pop(KNOWN_SETTINGS, "heavy_oracle"), dict.pop(KNOWN_SETTINGS, "heavy_file")
    assert forget_cli and "heavy_file" not in KNOWN_SETTINGS  # the command line reads the file itself
    out = tmp_path / "run"
    result = CliRunner().invoke(
        app,
        ["evaluate", "--settings-file", str(path), "--setting", "heavy_file", "--policies", "static", "--seeds", "7",
         "--episodes", "1", "--data", str(tiny_dataset), "--out", str(out)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    metadata = json.loads((out / "run_metadata.json").read_text())
    assert metadata["setting"] == "heavy_file" and metadata["config"]["reward"]["physics_penalty"] == 5.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("settings:\n  a:\n    lable: A\n", "settings.a.lable: unknown key"),
        ("settings:\n  a:\n    config: {reward.phys: 1}\n", "setting 'a': config override reward.phys: not a field"),
        ("settings:\n  a:\n    compare_with: [{base: nowhere, kind: x}]\n", "compare_with: unknown setting 'nowhere'"),
        ("settings:\n  main:\n    label: Mine\n", "settings.main: the paper's settings cannot be redeclared"),
        ("settings:\n  a:\n    governance: {auditor: psychic}\n", "setting 'a': governance: unknown auditor 'psychic'"),
    ],
)
def test_a_bad_settings_file_is_one_line_naming_the_file_and_field(text, message, tmp_path, forget):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    forget.append("a")
    with pytest.raises(SettingError) as error:
        load_settings(path)
    assert str(error.value).startswith(f"{path}: ") and message in str(error.value) and "\n" not in str(error.value)
    result = CliRunner().invoke(app, ["evaluate", "--settings-file", str(path), "--episodes", "1"])
    assert result.exit_code == 2 and message in " ".join(result.output.split())


def test_an_entry_point_declares_a_setting(monkeypatch, forget):
    plugin = EntryPoint("plugged", "test_settings_declared:PLUGIN_SETTING", settings_module.ENTRY_POINT_GROUP)
    monkeypatch.setattr(settings_module, "entry_points", lambda group: [plugin] if group == plugin.group else [])
    monkeypatch.setattr(KNOWN_SETTINGS, "_loaded", False)  # read the group again
    forget.append("plugged")
    assert KNOWN_SETTINGS["plugged"] is PLUGIN_SETTING
    spec = EvaluationSpec(policies=[], setting="plugged")
    assert spec.agentic.auditor == "oracle" and spec.setting == "plugged"

    wrong = EntryPoint("other", "test_settings_declared:PLUGIN_SETTING", settings_module.ENTRY_POINT_GROUP)
    monkeypatch.setattr(settings_module, "entry_points", lambda group: [wrong])
    monkeypatch.setattr(KNOWN_SETTINGS, "_loaded", False)
    with pytest.raises(SettingError, match=r"setting plugin other \(test_settings_declared:PLUGIN_SETTING\) is not"):
        "other" in KNOWN_SETTINGS  # noqa: B015


def test_the_grid_hands_workers_the_setting_and_its_governance(tiny_dataset, tmp_path, forget):
    from solarchain_eval.experiments.grid import GridSpec, plan_units
    from solarchain_eval.experiments.grid_root import unit_task

    forget.append("plugged")
    register_setting(PLUGIN_SETTING)
    spec = GridSpec.from_preset("smoke", seeds=(7,), settings=("plugged",), policies=("ppo",), data_dir=tiny_dataset)
    (unit,) = [u for u in plan_units(spec) if u.kind == "eval"]
    model = tmp_path / "units" / "train" / "ppo-main-7" / "model.zip"  # the unit hashes its model: a stand-in
    model.parent.mkdir(parents=True)
    model.write_bytes(b"")
    task = unit_task(spec, tmp_path, tiny_dataset, {}, unit, ["paper"])
    assert task.setting is PLUGIN_SETTING and task.agentic is PLUGIN_SETTING.governance


def test_the_command_lines_setting_and_reward_flag_must_agree(tiny_dataset, tmp_path):
    out = tmp_path / "run"
    result = CliRunner().invoke(
        app,
        ["evaluate", "--setting", "main", "--no-physics-penalty", "--policies", "static", "--seeds", "7",
         "--episodes", "1", "--data", str(tiny_dataset), "--out", str(out)],
    )  # fmt: skip
    assert result.exit_code == 2 and not out.exists()
    assert "setting 'main' has no_physics_penalty=False; the evaluation asks for True" in " ".join(
        result.output.split()
    )
