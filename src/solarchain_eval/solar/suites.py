"""The solar market's built-in suites (registered by name in :mod:`solarchain_eval.tasks.suites`).

- ``heldout``: the twelve months of the held-out family ``tmy-3sites``, the ``test`` split;
- ``train``: the paper's dataset (April 2026), the ``train`` split.

Each entry's dataset is found (and built offline on first use) by
:func:`solarchain_eval.data.splits.dataset_dir`. The within-month splits ``paper-early`` and
``paper-late`` have no suite: they restrict the days an episode starts on, which an evaluation's
environment does not do (it draws the start from every midnight of the dataset).
"""

from __future__ import annotations

import functools

from ..data.splits import dataset_dir as split_dataset_dir
from ..data.splits import get_split
from ..tasks.suites import Suite, SuiteEntry


def split_suite(name: str, split: str, description: str) -> Suite:
    """A suite of the solar market on every dataset of ``split`` (a split that keeps every start day)."""
    entries = []
    for entry in get_split(split).entries:
        if entry.start_days is not None:
            raise ValueError(f"split {split!r} restricts start days, which a suite cannot run")
        entries.append(SuiteEntry(entry.dataset, "solar", split, functools.partial(split_dataset_dir, entry.dataset)))
    return Suite(name, description, tuple(entries))


HELDOUT_SUITE = split_suite(
    "heldout", "test", "the solar market on the twelve held-out months of tmy-3sites (split test)"
)
TRAIN_SUITE = split_suite("train", "train", "the solar market on the paper's dataset, April 2026 (split train)")
