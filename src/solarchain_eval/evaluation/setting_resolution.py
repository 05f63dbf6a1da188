"""The one conversion from an evaluation's setting options to its :class:`~.settings.Setting`.

``EvaluationSpec`` (its ``setting``, and the older ``no_physics_penalty``, ``agentic`` and
``setting_label``), :func:`solarchain_eval.evaluate` and the command line's ``--setting`` all
reach their setting here, so they agree on it and on the one error when options disagree.
"""

from __future__ import annotations

from ..governance.factory import AgenticOptions
from .settings import KNOWN_SETTINGS, Setting, SettingError, get_setting, governed_counterpart, setting_name


def resolve_setting(
    setting: Setting | str | None = None,
    *,
    label: str | None = None,
    no_physics_penalty: bool | None = None,
    agentic: AgenticOptions | bool | None = None,
) -> tuple[Setting, AgenticOptions | None]:
    """The one conversion from an evaluation's setting options to its setting and Planner/Auditor options.

    ``setting`` (a :class:`Setting` or a registered name) decides; ``no_physics_penalty``, when
    given, must agree with it, and ``agentic`` options (True: the rule planner and auditor) govern
    an agentic setting (default: the setting's ``governance``) or turn a setting into its governed
    counterpart (``main`` -> ``llm``). Without ``setting``, the older spelling: ``label`` names a
    registered setting whose reward and governance must equal ``no_physics_penalty`` and
    ``agentic`` (absent: False and None), and without a label those two pick one of the paper's four.

    Raises
    ------
    SettingError
        An unknown setting, or options that disagree with it (one line naming both).
    """
    options = AgenticOptions() if agentic is True else (agentic or None)
    if setting is None and label is None:
        return KNOWN_SETTINGS[
            setting_name(agentic=options is not None, no_physics_penalty=bool(no_physics_penalty))
        ], options
    if setting is None:
        chosen = get_setting(label)  # type: ignore[arg-type]
        asked = (bool(no_physics_penalty), options is not None)
        if (chosen.no_physics_penalty, chosen.agentic) != asked:
            raise SettingError(
                f"setting {chosen.name!r} has no_physics_penalty={chosen.no_physics_penalty} and "
                f"agentic={chosen.agentic}; the evaluation asks for {asked[0]} and {asked[1]}"
            )
        return chosen, options
    chosen = setting if isinstance(setting, Setting) else get_setting(setting)
    if label is not None and label != chosen.name:
        raise SettingError(f"setting {chosen.name!r} and setting_label {label!r} name different settings")
    if no_physics_penalty is not None and bool(no_physics_penalty) != chosen.no_physics_penalty:
        raise SettingError(
            f"setting {chosen.name!r} has no_physics_penalty={chosen.no_physics_penalty}; "
            f"the evaluation asks for {bool(no_physics_penalty)}"
        )
    if options is not None and not chosen.agentic:
        counterpart = governed_counterpart(chosen.name)
        if counterpart is None:
            raise SettingError(f"setting {chosen.name!r} runs without the Planner/Auditor layer; drop agentic=")
        chosen = KNOWN_SETTINGS[counterpart]
    if chosen.agentic and options is None:
        options = chosen.governance or AgenticOptions()  # the paper's layer: rule planner and auditor
    return chosen, options
