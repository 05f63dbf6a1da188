"""What an evaluation *setting* is: the one definition rollouts, the grid and the report share.

A setting is the value of the ``setting`` column of every record, and one :class:`Setting`
object says everything about it: the reward (with or without the physics penalty λp (V + A)),
whether policies run behind the Planner/Auditor layer and with which options by default, which
training setting's models its learned policies use, the labels the report prints, the config
values it changes, and the settings the report compares it with (:class:`Contrast`).

The paper's four: ``main`` ("RL"), ``no_physics`` ("RL no-physics"), ``llm`` ("RL+LLM") and
``llm_no_physics`` ("RL+LLM no-physics"). More come from :func:`register_setting` (in Python),
from a settings file (:func:`load_settings`, the command line's ``--settings-file``) or from the
``solarchain_eval.settings`` entry-point group; the grid, the sweep, the governance diagnostics
and the report all read :data:`KNOWN_SETTINGS`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any

from pydantic import ValidationError

from ..agents.checkpoints import ALGOS, TRAINABLE_ALGOS
from ..common.errors import OptionsError
from ..config import BenchmarkConfig
from ..governance.factory import AgenticOptions
from ..tasks.base import Task
from ..tasks.registry import get_task

SETTING_MAIN = "main"
SETTING_NO_PHYSICS = "no_physics"
SETTING_AGENTIC = "llm"
SETTING_AGENTIC_NO_PHYSICS = "llm_no_physics"
#: Contrast kinds the report's tables know: RL+LLM - RL deltas, and no-physics - physics deltas.
GOVERNANCE_CONTRAST = "governance"
ABLATION_CONTRAST = "ablation"
ENTRY_POINT_GROUP = "solarchain_eval.settings"
#: A setting name goes into directory names (``eval/ppo-<setting>-<seed>``) and the records.
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}$")


class SettingError(OptionsError, ValueError):
    """A setting that is unknown, declared wrongly, or at odds with the evaluation's options."""


@dataclass(frozen=True)
class Contrast:
    """A comparison the report makes: the declaring setting (treated) against ``base``.

    Attributes
    ----------
    base : str
        The setting it is compared with (it must be registered).
    kind : str
        ``"governance"`` (the treated setting adds the Planner/Auditor layer: the RL+LLM - RL
        tables), ``"ablation"`` (it drops the physics penalty: the no-physics - physics tables),
        or a name of your own (listed by :func:`setting_pairs`, not yet drawn by the paper tables).
    meaning : str
        What the difference measures, in words.
    """

    base: str
    kind: str
    meaning: str = ""


@dataclass(frozen=True)
class Setting:
    """One evaluation setting.

    Attributes
    ----------
    name : str
        The ``setting`` column value (letters, digits and ``_ . + -``, at most 64 characters).
    no_physics_penalty : bool
        The reward switch: whether the reward drops λp (V + A) (V and A are still recorded).
    agentic : bool
        Whether policies run behind the Planner/Auditor layer.
    model_setting : str
        The training setting whose models its learned policies use ("main" or "no_physics").
    label : str
        The appendix's name for it ("Main", "LLM No-physics", ...).
    governance_label : str
        The body tables' name for it ("RL", "RL+LLM no-physics", ...).
    policies : tuple of str
        The policies a grid (``paper``, ``sweep``) evaluates in it by default; learned ones need
        their models. Opt-in algorithms (``ppo-lag``) run only when asked for.
    governance : AgenticOptions, optional
        The Planner/Auditor options of an agentic setting when the evaluation gives none (None:
        the rule planner and rule auditor). Only with ``agentic``.
    config_overrides : mapping
        ``BenchmarkConfig`` fields by dotted path (``"reward.physics_penalty"``; nested mappings
        are read the same way) -> value, applied on top of the run's config: they change its
        protocol. ``no_physics_penalty`` is the reward switch's, not an override.
    compare_with : tuple of Contrast
        The settings the report compares this one against.
    """

    name: str
    no_physics_penalty: bool
    agentic: bool
    model_setting: str
    label: str
    governance_label: str
    policies: tuple[str, ...] = ()
    governance: AgenticOptions | None = field(default=None, hash=False)
    config_overrides: Mapping[str, Any] = field(default_factory=dict, hash=False)
    compare_with: tuple[Contrast, ...] = ()

    def __post_init__(self) -> None:
        where = f"setting {self.name!r}"
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise SettingError(f"{where}: name must be letters, digits and '_ . + -' (at most 64 characters)")
        if self.model_setting not in TRAIN_SETTINGS:
            raise SettingError(f"{where}: model_setting must be one of {', '.join(TRAIN_SETTINGS)}")
        if self.governance is not None and not self.agentic:
            raise SettingError(f"{where}: governance needs agentic=True (the Planner/Auditor layer)")
        object.__setattr__(self, "policies", tuple(self.policies))
        object.__setattr__(self, "compare_with", tuple(self.compare_with))
        object.__setattr__(self, "config_overrides", _flat_overrides(where, self.config_overrides))
        if self.config_overrides:
            self.apply(BenchmarkConfig())  # each value checked against its field now, not at run time
        for contrast in self.compare_with:
            _check_contrast(self, contrast, None)

    def apply(self, config: Any, task: Task | None = None) -> Any:
        """``config`` of ``task`` (default: the solar market) as this setting runs it: its reward
        switch and its config overrides applied.

        Raises
        ------
        SettingError
            An override value that the config refuses (the message names the field).
        """
        task = task or get_task()
        if not self.config_overrides:  # the paper's settings: exactly the runner's config as before
            return task.setting_config(config, no_physics_penalty=self.no_physics_penalty)
        payload = task.config_record(task.setting_config(config, no_physics_penalty=self.no_physics_penalty))
        for path, value in self.config_overrides.items():
            *parents, leaf = path.split(".")
            holder = payload
            for part in parents:
                holder = holder[part]
            holder[leaf] = value
        try:
            return task.config_from_record(payload)
        except ValidationError as error:
            item = error.errors()[0]
            path = ".".join(str(p) for p in item["loc"]) or "<config>"
            raise SettingError(f"setting {self.name!r}: config override {path}: {item['msg']}") from None


def _flat_overrides(where: str, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Dotted path -> value, each path a ``BenchmarkConfig`` field (sub-sections walked)."""
    if not isinstance(overrides, Mapping):
        raise SettingError(f"{where}: config overrides must be a mapping of config fields to values")
    flat: dict[str, Any] = {}
    for key, value in overrides.items():
        path = str(key)
        model: Any = BenchmarkConfig
        for part in path.split("."):
            fields = getattr(model, "model_fields", None)
            if fields is None or part not in fields:
                raise SettingError(f"{where}: config override {path}: not a field of the benchmark config")
            model = fields[part].annotation
        if path == "no_physics_penalty":
            raise SettingError(f"{where}: config override {path}: set the setting's no_physics_penalty instead")
        if isinstance(value, Mapping) and hasattr(model, "model_fields"):  # a section given as a mapping
            flat.update(_flat_overrides(where, {f"{path}.{k}": v for k, v in value.items()}))
        else:
            flat[path] = value
    return flat


def _check_contrast(setting: Setting, contrast: Contrast, known: Mapping[str, Setting] | None) -> None:
    """A contrast's own shape; with ``known``, also that its base is registered and fits its kind."""
    where = f"setting {setting.name!r}: compare_with"
    if not isinstance(contrast, Contrast):
        raise SettingError(f"{where}: {contrast!r} is not a Contrast(base, kind, meaning)")
    if contrast.base == setting.name:
        raise SettingError(f"{where}: a setting is not compared with itself")
    if known is None:
        return
    base = known.get(contrast.base)
    if base is None:
        raise SettingError(f"{where}: unknown setting {contrast.base!r} (registered: {', '.join(known)})")
    if contrast.kind == GOVERNANCE_CONTRAST and not (setting.agentic and not base.agentic):
        raise SettingError(f"{where}: a governance contrast pairs an agentic setting with a non-agentic base")
    if contrast.kind == ABLATION_CONTRAST and not (setting.no_physics_penalty and not base.no_physics_penalty):
        raise SettingError(f"{where}: an ablation contrast pairs a no-physics setting with a physics-penalised base")


#: Settings that train models (each setting's ``model_setting`` is one of them).
TRAIN_SETTINGS = (SETTING_MAIN, SETTING_NO_PHYSICS)
_EVERY_POLICY = (*get_task().baselines(), *TRAINABLE_ALGOS)
_PAPER = (
    Setting(SETTING_MAIN, False, False, SETTING_MAIN, "Main", "RL", _EVERY_POLICY),
    Setting(
        SETTING_NO_PHYSICS,
        True,
        False,
        SETTING_NO_PHYSICS,
        "No-physics",
        "RL no-physics",
        _EVERY_POLICY,
        compare_with=(Contrast(SETTING_MAIN, ABLATION_CONTRAST, "dropping λp (V + A) from the reward"),),
    ),
    Setting(
        SETTING_AGENTIC,
        False,
        True,
        SETTING_MAIN,
        "LLM Main",
        "RL+LLM",
        ALGOS,
        compare_with=(Contrast(SETTING_MAIN, GOVERNANCE_CONTRAST, "adding the Planner/Auditor layer"),),
    ),
    Setting(
        SETTING_AGENTIC_NO_PHYSICS,
        True,
        True,
        SETTING_NO_PHYSICS,
        "LLM No-physics",
        "RL+LLM no-physics",
        ALGOS,
        compare_with=(
            Contrast(SETTING_NO_PHYSICS, GOVERNANCE_CONTRAST, "adding the Planner/Auditor layer"),
            Contrast(SETTING_AGENTIC, ABLATION_CONTRAST, "dropping λp (V + A) from the reward"),
        ),
    ),
)
#: The paper's settings in the report's order.
SETTINGS = tuple(s.name for s in _PAPER)
#: Appendix labels of the paper's settings.
SETTING_LABELS = {s.name: s.label for s in _PAPER}
#: The paper's settings that run behind the Planner/Auditor layer.
AGENTIC_SETTINGS = tuple(s.name for s in _PAPER if s.agentic)


class _Registry(dict):
    """:data:`KNOWN_SETTINGS`: a dict that adds the entry-point group's settings on its first read
    (not at import, so a plugin module may import this one)."""

    _loaded = False

    def _load(self) -> None:
        if self._loaded:
            return
        self._loaded = True
        for ep in entry_points(group=ENTRY_POINT_GROUP):
            try:
                loaded = ep.load()
            except Exception as error:  # a broken plugin is the user's error, named
                raise SettingError(f"setting plugin {ep.name} ({ep.value}): {type(error).__name__}: {error}") from None
            if not isinstance(loaded, Setting) or loaded.name != ep.name:
                raise SettingError(f"setting plugin {ep.name} ({ep.value}) is not a Setting named {ep.name!r}")
            _add(loaded, source=f"setting plugin {ep.name}")

    def __getitem__(self, key: str) -> Setting:
        self._load()
        return super().__getitem__(key)

    def __contains__(self, key: object) -> bool:
        self._load()
        return super().__contains__(key)

    def __iter__(self) -> Iterator[str]:
        self._load()
        return super().__iter__()

    def __len__(self) -> int:
        self._load()
        return super().__len__()

    def get(self, key: str, default: Any = None) -> Any:
        self._load()
        return super().get(key, default)

    def keys(self):  # type: ignore[override]
        self._load()
        return super().keys()

    def values(self):  # type: ignore[override]
        self._load()
        return super().values()

    def items(self):  # type: ignore[override]
        self._load()
        return super().items()


KNOWN_SETTINGS: dict[str, Setting] = _Registry({s.name: s for s in _PAPER})


def _add(setting: Setting, *, source: str) -> None:
    """Register a declared setting (a file's or a plugin's): the paper's four are not replaced."""
    if setting.name in SETTINGS:
        raise SettingError(f"{source}: {setting.name!r} is one of the paper's settings and cannot be redeclared")
    register_setting(setting)


def register_setting(setting: Setting) -> None:
    """Add (or replace) a setting; the settings it compares with must be registered already.

    Raises
    ------
    SettingError
        A ``compare_with`` naming an unknown setting or not fitting its kind (a ``ValueError``).
    """
    if not isinstance(setting, Setting):
        raise SettingError(f"register_setting takes a Setting, not {type(setting).__name__}")
    known = dict(KNOWN_SETTINGS.items())
    for contrast in setting.compare_with:
        _check_contrast(setting, contrast, known)
    dict.__setitem__(KNOWN_SETTINGS, setting.name, setting)


def get_setting(name: str) -> Setting:
    """The registered setting called ``name``; an unknown name is a :class:`SettingError` listing the known ones."""
    known = KNOWN_SETTINGS.get(name)
    if known is None:
        raise SettingError(f"unknown setting {name!r} (registered: {', '.join(KNOWN_SETTINGS)})")
    return known


def setting_pairs(kind: str | None = None, names: Iterable[str] | None = None) -> list[tuple[str, str, Contrast]]:
    """``(base, treated, contrast)`` for every contrast declared by the settings ``names`` (default:
    every registered one), in their order, of ``kind`` when given: what the report compares."""
    chosen = list(names) if names is not None else list(KNOWN_SETTINGS)
    return [
        (c.base, name, c)
        for name in chosen
        for c in KNOWN_SETTINGS[name].compare_with
        if kind is None or c.kind == kind
    ]


def governed_counterpart(name: str) -> str | None:
    """The setting that adds the Planner/Auditor layer to ``name`` (its declared governance contrast), if any."""
    for base, treated, _ in setting_pairs(GOVERNANCE_CONTRAST):
        if base == name:
            return treated
    return None


def setting_name(*, agentic: bool, no_physics_penalty: bool) -> str:
    """The paper's setting with this reward and governance."""
    if agentic:
        return SETTING_AGENTIC_NO_PHYSICS if no_physics_penalty else SETTING_AGENTIC
    return SETTING_NO_PHYSICS if no_physics_penalty else SETTING_MAIN


def setting_has_physics_penalty(setting: str) -> bool:
    """Whether ``setting``'s reward charges λp (V + A) (False for unknown names)."""
    known = KNOWN_SETTINGS.get(setting)
    return known is not None and not known.no_physics_penalty


def setting_is_agentic(setting: str) -> bool:
    """Whether ``setting`` runs policies behind the Planner/Auditor layer (False for unknown names)."""
    known = KNOWN_SETTINGS.get(setting)
    return known is not None and known.agentic


__all__ = [
    "ABLATION_CONTRAST",
    "AGENTIC_SETTINGS",
    "ENTRY_POINT_GROUP",
    "GOVERNANCE_CONTRAST",
    "KNOWN_SETTINGS",
    "SETTINGS",
    "SETTING_AGENTIC",
    "SETTING_AGENTIC_NO_PHYSICS",
    "SETTING_LABELS",
    "SETTING_MAIN",
    "SETTING_NO_PHYSICS",
    "TRAIN_SETTINGS",
    "Contrast",
    "Setting",
    "SettingError",
    "get_setting",
    "governed_counterpart",
    "register_setting",
    "setting_has_physics_penalty",
    "setting_is_agentic",
    "setting_name",
    "setting_pairs",
]
