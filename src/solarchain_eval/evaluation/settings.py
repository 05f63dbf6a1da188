"""What an evaluation *setting* is: the one definition rollouts, the grid and the report share.

A setting is the value of the ``setting`` column of every record. It fixes the reward (with or
without the physics penalty λp (V + A)), whether policies run behind the Planner/Auditor layer,
which training setting's models its learned policies use, and the labels the report prints.
The paper's four: ``main`` ("RL"), ``no_physics`` ("RL no-physics"), ``llm`` ("RL+LLM") and
``llm_no_physics`` ("RL+LLM no-physics"). :func:`register_setting` adds more; the grid, the
sweep, the governance diagnostics and the report all read :data:`KNOWN_SETTINGS`.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..agents.checkpoints import ALGOS, TRAINABLE_ALGOS
from ..market.baselines import BASELINES

SETTING_MAIN = "main"
SETTING_NO_PHYSICS = "no_physics"
SETTING_AGENTIC = "llm"
SETTING_AGENTIC_NO_PHYSICS = "llm_no_physics"


@dataclass(frozen=True)
class Setting:
    """One evaluation setting.

    Attributes
    ----------
    name : str
        The ``setting`` column value.
    no_physics_penalty : bool
        Whether the reward drops λp (V + A) (V and A are still recorded).
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
    """

    name: str
    no_physics_penalty: bool
    agentic: bool
    model_setting: str
    label: str
    governance_label: str
    policies: tuple[str, ...] = ()


_EVERY_POLICY = (*BASELINES, *TRAINABLE_ALGOS)

KNOWN_SETTINGS: dict[str, Setting] = {
    s.name: s
    for s in (
        Setting(SETTING_MAIN, False, False, SETTING_MAIN, "Main", "RL", _EVERY_POLICY),
        Setting(SETTING_NO_PHYSICS, True, False, SETTING_NO_PHYSICS, "No-physics", "RL no-physics", _EVERY_POLICY),
        Setting(SETTING_AGENTIC, False, True, SETTING_MAIN, "LLM Main", "RL+LLM", ALGOS),
        Setting(
            SETTING_AGENTIC_NO_PHYSICS, True, True, SETTING_NO_PHYSICS, "LLM No-physics", "RL+LLM no-physics", ALGOS
        ),
    )
}
#: The paper's settings in the report's order.
SETTINGS = (SETTING_MAIN, SETTING_NO_PHYSICS, SETTING_AGENTIC, SETTING_AGENTIC_NO_PHYSICS)
#: Settings that train models (each setting's ``model_setting`` is one of them).
TRAIN_SETTINGS = (SETTING_MAIN, SETTING_NO_PHYSICS)
#: Appendix labels of the paper's settings.
SETTING_LABELS = {name: KNOWN_SETTINGS[name].label for name in SETTINGS}
#: The paper's settings that run behind the Planner/Auditor layer.
AGENTIC_SETTINGS = tuple(name for name in SETTINGS if KNOWN_SETTINGS[name].agentic)


def register_setting(setting: Setting) -> None:
    """Add (or replace) a setting; its ``model_setting`` must be a training setting."""
    if setting.model_setting not in TRAIN_SETTINGS:
        raise ValueError(f"setting '{setting.name}': model_setting must be one of {', '.join(TRAIN_SETTINGS)}")
    KNOWN_SETTINGS[setting.name] = setting


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
