"""The solar market's built-in suites (registered by name in :mod:`solarchain_eval.tasks.suites`).

- ``heldout``: the twelve months of the held-out family ``tmy-3sites``, the ``test`` split;
- ``train``: the paper's dataset (April 2026), the ``train`` split;
- ``paper-early`` and ``paper-late``: the paper's dataset, episodes starting on days 1-21 and
  22-30 (the within-month splits): the entry fixes the configuration's ``start_days``.

Each entry's dataset is found (and built offline on first use) by
:func:`solarchain_eval.data.splits.dataset_dir`.
"""

from __future__ import annotations

import functools

from ..data.splits import dataset_dir as split_dataset_dir
from ..data.splits import get_split
from ..tasks.suites import Suite, SuiteEntry


def split_suite(name: str, split: str, description: str) -> Suite:
    """A suite of the solar market on every dataset of ``split``; a split that keeps some start days
    fixes them in its entries' configuration (``start_days``), so they enter each run's protocol."""
    entries = []
    for entry in get_split(split).entries:
        overrides = {} if entry.start_days is None else {"start_days": list(entry.start_days)}
        data = functools.partial(split_dataset_dir, entry.dataset)
        entries.append(SuiteEntry(entry.dataset, "solar", split, data, overrides))
    return Suite(name, description, tuple(entries))


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
