"""Suites by name: lists of tasks an agent is evaluated over together (docs/suites.md).

A suite is a named list of entries, each one task (a market, by name) on one dataset of one
split (:mod:`solarchain_eval.data.splits` for the solar market). Its score per entry is
normalised on the entry's own baselines, ``(score - lower) / (upper - lower)`` with ``lower``
and ``upper`` the mean score of the two reference baselines (Random and Myopic by default), so
that scores of different months and climates can be aggregated.

As with :mod:`.registry`, built-in suites are named here with the module that defines them and
imported on first use (the module path is data: a generic wing never imports a task's modules);
code running in-process (a test, a notebook) adds suites through :func:`register_suite`.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..common.errors import OptionsError
from .registry import get_task

#: Built-in suites: name -> "module:attribute" of the Suite object.
BUILTIN_SUITES = {
    "heldout": "solarchain_eval.solar.suites:HELDOUT_SUITE",
    "train": "solarchain_eval.solar.suites:TRAIN_SUITE",
    "paper-early": "solarchain_eval.solar.suites:PAPER_EARLY_SUITE",
    "paper-late": "solarchain_eval.solar.suites:PAPER_LATE_SUITE",
    "paper-cities": "solarchain_eval.solar.suites:PAPER_CITIES_SUITE",
}
_NAME = re.compile(r"^[a-z][a-z0-9-]{0,39}$")

_registered: dict[str, Suite] = {}


class SuiteError(OptionsError, ValueError):
    """A suite that cannot run as asked (one line naming what is at fault)."""


class UnknownSuiteError(SuiteError):
    """A suite name that no built-in suite or :func:`register_suite` call provides."""


@dataclass(frozen=True)
class SuiteEntry:
    """One task of a suite.

    Attributes
    ----------
    name : str
        The entry's name, unique in its suite: its run directory under the suite's root.
    task : str
        The market, by name (:func:`~solarchain_eval.tasks.registry.get_task`).
    split : str
        The split its dataset belongs to (``train``, ``test``, ...): recorded in the suite root.
    data : path or callable
        The dataset directory, or a function returning it (called when the suite runs, so that a
        dataset built on first use is built only then).
    config_overrides : mapping
        Top-level fields of the task's configuration the entry fixes (``{"start_days": [22, ...]}``
        for a split that keeps some start days): they enter the entry's run protocol.
    """

    name: str
    task: str
    split: str
    data: Path | str | Callable[[], Path]
    config_overrides: Mapping[str, Any] = field(default_factory=dict, hash=False)

    def data_dir(self) -> Path:
        """The entry's dataset directory (building it when ``data`` is a function that does)."""
        return Path(self.data() if callable(self.data) else self.data)

    def configure(self, config: Any) -> Any:
        """The configuration the entry runs: ``config`` (None: the task's default) with the entry's
        overrides applied; None stays None when the entry has none.

        Raises
        ------
        SuiteError
            ``config`` itself sets a field the entry fixes, to another value (say, ``start_days``
            from ``--config`` on a suite of a within-month split).
        """
        if not self.config_overrides:
            return config
        task = get_task(self.task)
        default = task.config_record(task.default_config())
        record = task.config_record(task.default_config() if config is None else config)
        for key, value in self.config_overrides.items():
            if record.get(key) != default.get(key) and record.get(key) != value:
                raise SuiteError(
                    f"entry {self.name!r} fixes {key} = {value!r}; the configuration given sets {key} = "
                    f"{record.get(key)!r} (leave {key} out of it to run this suite)"
                )
        return task.config_from_record({**record, **self.config_overrides})


@dataclass(frozen=True)
class Suite:
    """A named list of :class:`SuiteEntry` and the normalisation of its scores.

    Attributes
    ----------
    name : str
        ``--suite NAME``.
    description : str
        One line for listings and the suite root.
    entries : tuple of SuiteEntry
        The tasks, in order (names unique).
    reference : tuple of (str, str)
        The baselines a normalised score of 0 and 1 stand for, by name (run on every entry).
    online : bool
        Its datasets are downloaded on first use (built from the cache afterwards), so that
        ``bench-suite``, which times the offline builds, builds them only when named.
    """

    name: str
    description: str
    entries: tuple[SuiteEntry, ...]
    reference: tuple[str, str] = ("random", "myopic")
    online: bool = False

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise ValueError(f"suite name {self.name!r}: use lowercase letters, digits and '-' (at most 40)")
        names = [entry.name for entry in self.entries]
        if not names or len(set(names)) != len(names):
            raise ValueError(f"suite {self.name!r}: give one or more entries with distinct names")
        if len(set(self.reference)) != 2:
            raise ValueError(f"suite {self.name!r}: the reference names two different baselines")

    def with_reference(self, policies: Sequence[Any]) -> list[Any]:
        """``policies`` followed by the reference baselines not among them already (by name)."""
        named = {p for p in policies if isinstance(p, str)}
        return [*policies, *(name for name in self.reference if name not in named)]

    @property
    def splits(self) -> tuple[str, ...]:
        """The splits of its entries, sorted, each once."""
        return tuple(sorted({entry.split for entry in self.entries}))


def register_suite(suite: Suite) -> None:
    """Make ``suite`` available by its name in this process (replacing one of the same name)."""
    _registered[suite.name] = suite


def unregister_suite(name: str) -> None:
    """Forget a suite :func:`register_suite` added (built-in suites cannot be removed)."""
    _registered.pop(name, None)


def suite_names() -> tuple[str, ...]:
    """Every available suite's name: built-in and registered in this process."""
    return tuple(dict.fromkeys([*BUILTIN_SUITES, *_registered]))


def get_suite(name: str) -> Suite:
    """The suite called ``name``.

    Raises
    ------
    UnknownSuiteError
        No suite has that name (the message lists the available ones).
    """
    if name in _registered:
        return _registered[name]
    target = BUILTIN_SUITES.get(name)
    if target is None:
        raise UnknownSuiteError(f"unknown suite {name!r} (available: {', '.join(suite_names())})")
    module, _, attribute = target.partition(":")
    suite = getattr(importlib.import_module(module), attribute)
    _registered[name] = suite
    return suite
