"""Settings declared in a YAML file (the command line's ``--settings-file``; docs/settings.md).

For example::

    settings:
      heavy_physics:
        label: Heavy physics
        governance_label: RL heavy physics
        config:
          reward.physics_penalty: 4.0
        compare_with:
          - {base: main, kind: physics_weight, meaning: four times λp instead of two}

Each entry becomes a :class:`~.settings.Setting` (the keys are its fields; ``config`` holds its
config overrides, ``governance`` its Planner/Auditor options) and is registered in order, so an
entry may compare with one declared above it. The file is read like a config file (YAML, unknown
and repeated keys refused); an error is one line naming the file and the entry's field.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..agents.checkpoints import ALGOS
from ..config import _read_text, _UniqueKeyLoader
from ..governance.errors import GovernanceConfigError
from ..governance.factory import AgenticOptions
from .settings import (
    KNOWN_SETTINGS,
    SETTING_MAIN,
    SETTING_NO_PHYSICS,
    SETTINGS,
    Contrast,
    Setting,
    SettingError,
    register_setting,
)


class _Declared(BaseModel):
    model_config = ConfigDict(extra="forbid")


class _Contrast(_Declared):
    base: str
    kind: str
    meaning: str = ""


class _Governance(_Declared):
    """The Planner/Auditor options a file may fix (an LLM planner or auditor needs the command line's endpoint)."""

    planner: str = "rule"
    auditor: str = "rule"
    diagnostics: bool = True
    target_audit_rate: float | None = None
    random_audit_rate: float | None = None
    random_seed: int = 0
    oracle_reward_loss: float | None = None


class _Setting(_Declared):
    label: str | None = None
    governance_label: str | None = None
    no_physics_penalty: bool = False
    agentic: bool | None = None
    governance: _Governance | None = None
    model_setting: str | None = None
    policies: list[str] | None = None
    config: dict[str, Any] = Field(default_factory=dict)
    compare_with: list[_Contrast] = Field(default_factory=list)


class _File(_Declared):
    settings: dict[str, _Setting] = Field(min_length=1)


def _setting(name: str, declared: _Setting) -> Setting:
    agentic = declared.agentic if declared.agentic is not None else declared.governance is not None
    governance = None
    if declared.governance is not None:
        given = declared.governance.model_dump(exclude_none=True)
        try:
            governance = AgenticOptions(**given)
        except (GovernanceConfigError, ValueError) as error:
            raise SettingError(f"setting {name!r}: governance: {error}") from None
    # Defaults as the paper's: models of the setting with the same reward, and its policies.
    model_setting = declared.model_setting or (SETTING_NO_PHYSICS if declared.no_physics_penalty else SETTING_MAIN)
    policies = (
        declared.policies
        if declared.policies is not None
        else (ALGOS if agentic else KNOWN_SETTINGS[SETTING_MAIN].policies)
    )
    label = declared.label or name
    return Setting(
        name,
        declared.no_physics_penalty,
        agentic,
        model_setting,
        label,
        declared.governance_label or label,
        tuple(policies),
        governance=governance,
        config_overrides=declared.config,
        compare_with=tuple(Contrast(c.base, c.kind, c.meaning) for c in declared.compare_with),
    )


def load_settings(path: str | Path) -> list[Setting]:
    """Read the settings file ``path`` and register its settings (in order); the paper's four cannot be redeclared.

    Returns
    -------
    list of Setting
        The settings it declared.

    Raises
    ------
    SettingError
        An unreadable or invalid file, an unknown key, config field or compare target (one line
        naming the file and the field).
    """
    source = Path(path)
    try:
        text = _read_text(source)
        payload = yaml.load(text, Loader=_UniqueKeyLoader)  # a SafeLoader subclass
    except yaml.YAMLError as error:
        raise SettingError(f"{source} is not valid YAML: {' '.join(str(error).split())}") from None
    except ValueError as error:  # the config reader's one-line errors (missing, unreadable, not UTF-8)
        raise SettingError(str(error)) from None
    try:
        declared = _File.model_validate(payload if payload is not None else {})
    except ValidationError as error:
        item = error.errors()[0]
        where = ".".join(str(p) for p in item["loc"]) or "<top level>"
        problem = "unknown key" if item["type"] == "extra_forbidden" else item["msg"]
        raise SettingError(f"{source}: {where}: {problem}") from None
    settings = []
    for name, entry in declared.settings.items():
        if name in SETTINGS:
            raise SettingError(f"{source}: settings.{name}: the paper's settings cannot be redeclared")
        try:
            setting = _setting(name, entry)
            register_setting(setting)
        except SettingError as error:
            raise SettingError(f"{source}: {error}") from None
        settings.append(setting)
    return settings
