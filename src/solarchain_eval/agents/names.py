"""The one rule for agent names, wherever a name comes from: ``NAME=spec`` on the command line,
``name=`` in Python, an agent's own ``name`` attribute, its class, function or plugin name.

A name becomes the ``policy`` column of every record, a unit directory of a grid, a row of the
Markdown and HTML leaderboards and a key of ``run_metadata.json``, so it is kept to characters
that are safe in all of them: letters, digits and ``_ . + -``, starting with a letter or digit,
at most :data:`MAX_NAME_CHARS` characters. (No ``/``, ``,``, ``=``, ``|``, ``<``, spaces or
newlines: each breaks a path, a ``--policies`` list, a table row or an HTML page.)

This module imports nothing from the package, so the adapters and the spec parser share it.
"""

from __future__ import annotations

import re

MAX_NAME_CHARS = 64
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")
#: What the rule allows, in words (the end of every refusal).
NAME_RULE = f"use letters, digits and _ . + - (starting with a letter or digit, at most {MAX_NAME_CHARS} characters)"


def is_valid_name(name: object) -> bool:
    """Whether ``name`` is a string that follows the rule (see the module docstring)."""
    return isinstance(name, str) and len(name) <= MAX_NAME_CHARS and _NAME.match(name) is not None


def name_problem(name: object) -> str | None:
    """Why ``name`` cannot name an agent (one line), or None when it can."""
    if is_valid_name(name):
        return None
    shown = (
        repr(name) if not isinstance(name, str) or len(name) <= MAX_NAME_CHARS else repr(name[:MAX_NAME_CHARS]) + "..."
    )
    return f"agent name {shown}: {NAME_RULE}"
