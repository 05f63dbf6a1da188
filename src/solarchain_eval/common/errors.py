"""Errors that name options: by field name in the library, by flag on the command line.

A library error about an argument names the argument as the library knows it (``overwrite``,
``llm_cache_mode``); the command line shows the flag the user typed (``--overwrite``,
``--llm-cache-mode``). Such an error is raised with :meth:`NamesOptions.about`, a template whose
``{opt_<field>}`` placeholders stand for options and whose other placeholders are values::

    raise TrainingError.about("{out_dir} holds a different training; pass {opt_overwrite}", out_dir=path)

``str(error)`` names the field (``... pass overwrite``); the CLI renders the same template with
:meth:`NamesOptions.message_for` and its flags (``... pass --overwrite``). Values are never parsed
as templates, so a path with braces in it is shown as it is.
"""

from __future__ import annotations

import string
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

E = TypeVar("E", bound="NamesOptions")

OPTION_PREFIX = "opt_"


class _OptionFormatter(string.Formatter):
    def __init__(self, name_of: Callable[[str], str]) -> None:
        super().__init__()
        self._name_of = name_of

    def get_value(self, key: Any, args: Any, kwargs: Mapping[str, Any]) -> Any:
        if isinstance(key, str) and key.startswith(OPTION_PREFIX):
            return self._name_of(key[len(OPTION_PREFIX) :])
        return super().get_value(key, args, kwargs)


def render(template: str, values: Mapping[str, Any], name_of: Callable[[str], str] | None = None) -> str:
    """``template`` with its values filled in and each ``{opt_<field>}`` replaced by ``name_of(field)``
    (default: the field name itself)."""
    return _OptionFormatter(name_of or (lambda field: field)).format(template, **values)


def flag_of(field: str) -> str:
    """The command-line flag of a field by typer's convention: ``llm_cache_mode`` -> ``--llm-cache-mode``."""
    return "--" + field.replace("_", "-")


class NamesOptions(Exception):
    """Mixin of errors whose message names options (see the module docstring)."""

    template: str | None = None
    values: Mapping[str, Any] = {}

    @classmethod
    def about(cls: type[E], template: str, **values: Any) -> E:
        """The error with message ``template`` (``{opt_<field>}`` placeholders name options)."""
        error = cls(render(template, values))
        error.template, error.values = template, values
        return error

    def message_for(self, name_of: Callable[[str], str] = flag_of) -> str:
        """The message with each option named by ``name_of`` (flags by default); ``str(self)`` if the
        error was raised with a plain message."""
        if self.template is None:
            return str(self)
        return render(self.template, self.values, name_of)
