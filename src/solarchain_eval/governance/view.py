"""How the governance layer obtains the market it governs: a task's governance view.

Every component takes a :class:`~solarchain_eval.tasks.governance_view.GovernanceView`. Callers
that pass a benchmark config (or its market section) instead, as every caller did before tasks,
get the default task's view of that config (:data:`~solarchain_eval.tasks.registry.DEFAULT_TASK`,
the solar market).
"""

from __future__ import annotations

import functools
from typing import Any

from ..tasks.governance_view import GovernanceView, governance_view_of
from ..tasks.registry import get_task


def resolve_view(view_or_config: Any = None) -> GovernanceView:
    """``view_or_config`` if it is a view, else the default task's view of that config (None: its default)."""
    if isinstance(view_or_config, GovernanceView):
        return view_or_config
    return governance_view_of(get_task(), view_or_config)


@functools.cache
def default_view() -> GovernanceView:
    """The default task's view of its default config (for the config-free parts: prompts, costs)."""
    return resolve_view(None)
