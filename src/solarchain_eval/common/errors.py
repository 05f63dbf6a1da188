"""The package's errors: one base, user errors by type, and errors that name options.

Every exception the package raises on purpose derives from :class:`SolarChainError` through one
of its types, each a kind of user mistake or of trouble outside the package:

- :class:`InputDataError`: a file, folder or record given to the package is missing, malformed or
  inconsistent (a dataset, a weather payload, a run directory to report, rank or verify, a model
  file, a recorded LLM response, a request to the local model server);
- :class:`OptionsError`: an option, a configuration file or a combination of them is invalid;
- :class:`UserAgentError`: a user's agent cannot take part or failed while it was driven;
- :class:`RefusedError`: an untrusted submission (a pickled model, a tarball) refused before
  anything in it is run or extracted;
- :class:`ServiceError`: a service the run needs is unavailable or failed (an LLM endpoint or the
  local model server, a Ray cluster).

Each error class keeps its builtin base too (``ValueError``, ``FileNotFoundError``,
``RuntimeError``, ``pickle.UnpicklingError``), so catching that still works. A bug is never a
:class:`SolarChainError`: the command line prints any of these as one line and exits with status 2,
and shows everything else as a traceback. Internal signals that never leave the module raising
them stay outside the base, so that one escaping by mistake shows its traceback (today only
``llm.serving.jump_forward._OutOfTokens``, which ends a decoding loop).

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


class SolarChainError(Exception):
    """Base of every error the package raises on purpose: a user's mistake or an unavailable service."""


class InputDataError(SolarChainError):
    """A file, folder or record given to the package is missing, malformed or inconsistent."""


class OptionsError(SolarChainError):
    """An option, a configuration file or a combination of them is invalid."""


class UserAgentError(SolarChainError):
    """A user's agent cannot take part as given, or failed while it was driven."""


class RefusedError(SolarChainError):
    """An untrusted submission refused before anything in it is run or extracted."""


class ServiceError(SolarChainError):
    """A service the run needs is unavailable or failed (an LLM endpoint, a local server, a Ray cluster)."""


class NamesOptions(SolarChainError):
    """Mixin of errors whose message names options (see the module docstring); each error class
    that uses it also derives from one of the types above."""

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
