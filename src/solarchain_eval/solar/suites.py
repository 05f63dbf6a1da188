"""The solar market's built-in suites (registered by name in :mod:`solarchain_eval.tasks.suites`).

- ``heldout``: the twelve months of the held-out family ``tmy-3sites``, the ``test`` split;
- ``paper-cities``: the paper's five cities in 2026-05 to 2026-10 (the held-out family
  ``paper-cities``, weather from Open-Meteo's archive, built online once), its split;
- ``train``: the paper's dataset (April 2026), the ``train`` split;
- ``paper-early`` and ``paper-late``: the paper's dataset, episodes starting on days 1-21 and
  22-30 (the within-month splits): the entry fixes the configuration's ``start_days``.

Each entry's dataset is found (and built on first use, offline except ``paper-cities``) by
:func:`solarchain_eval.data.splits.dataset_dir`.
"""

from __future__ import annotations

import functools

from ..data.splits import dataset_dir as split_dataset_dir
from ..data.splits import get_split
from ..tasks.suites import Suite, SuiteEntry


def split_suite(name: str, split: str, description: str, online: bool = False) -> Suite:
    """A suite of the solar market on every dataset of ``split``; a split that keeps some start days
    fixes them in its entries' configuration (``start_days``), so they enter each run's protocol.
    ``online``: the split's datasets are downloaded on first use."""
    entries = []
    for entry in get_split(split).entries:
        overrides = {} if entry.start_days is None else {"start_days": list(entry.start_days)}
        data = functools.partial(split_dataset_dir, entry.dataset)
        entries.append(SuiteEntry(entry.dataset, "solar", split, data, overrides))
    return Suite(name, description, tuple(entries), online=online)


HELDOUT_SUITE = split_suite(
    "heldout", "test", "the solar market on the twelve held-out months of tmy-3sites (split test)"
)
TRAIN_SUITE = split_suite("train", "train", "the solar market on the paper's dataset, April 2026 (split train)")
PAPER_EARLY_SUITE = split_suite(
    "paper-early", "paper-early", "the solar market on the paper's dataset, episodes starting on days 1-21"
)
PAPER_LATE_SUITE = split_suite(
    "paper-late", "paper-late", "the solar market on the paper's dataset, episodes starting on days 22-30"
)
PAPER_CITIES_SUITE = split_suite(
    "paper-cities",
    "paper-cities",
    "the solar market on the paper's five cities, 2026-05 to 2026-10 (split paper-cities; Open-Meteo, built online once)",
    online=True,
)
