"""The Planner/Auditor layer's option error: an unknown planner, auditor or trigger set, or a
control out of range. Problems with LLM settings stay :class:`~solarchain_eval.llm.errors.LLMConfigError`."""

from __future__ import annotations

from ..common.errors import OptionsError


class GovernanceConfigError(OptionsError, RuntimeError):
    """An invalid option of the Planner/Auditor layer (the message names it and, where there are
    some, the choices).

    A ``RuntimeError`` as well, as these problems were when they were raised as ``LLMConfigError``,
    so that code catching them as such still does.
    """
