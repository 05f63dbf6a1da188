"""Named splits of the benchmark's datasets (docs/dataset.md#splits).

The rule for a result that claims generality: **train and tune on ``train`` only**, and report
``test``. Users who must stay on the paper's data split its month by start day instead
(``paper-early`` to train and tune, ``paper-late`` to report). ``paper-cities`` reports the
paper's own market in the six months after its month. A split lists datasets and, per
dataset, the days an episode may start on (1 = the dataset's first midnight); ``None`` means
every start day the dataset has.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .heldout import TMY_FAMILY, family_datasets, heldout_dataset_dir
from .paper_cities import PAPER_CITIES_FAMILY, PAPER_CITIES_MONTHS, paper_cities_dataset_dir
from .paper_cities import family_datasets as paper_cities_datasets

#: The rule the docs state for results that claim generality.
SPLIT_RULE = "train and tune on the train split only; report the test split"
#: The name a split uses for the paper's dataset (April 2026, built by the default data build).
PAPER_DATASET = "paper-2026-04"
#: The paper's month splits at this start day: days 1-21 to train and tune, 22-30 to report.
PAPER_LAST_EARLY_DAY = 21
PAPER_DAYS = 30


@dataclass(frozen=True)
class SplitEntry:
    """One dataset of a split and the days its episodes may start on (None: all of them)."""

    dataset: str
    start_days: tuple[int, ...] | None = None

    def start_hours(self) -> tuple[int, ...] | None:
        """The start days as the environment's ``start_hour`` options (hours after the first midnight)."""
        return None if self.start_days is None else tuple(24 * (day - 1) for day in self.start_days)


@dataclass(frozen=True)
class Split:
    """A named split: what it is for and its datasets."""

    name: str
    role: str
    description: str
    entries: tuple[SplitEntry, ...]

    @property
    def datasets(self) -> tuple[str, ...]:
        return tuple(entry.dataset for entry in self.entries)


_EARLY = tuple(range(1, PAPER_LAST_EARLY_DAY + 1))
_LATE = tuple(range(PAPER_LAST_EARLY_DAY + 1, PAPER_DAYS + 1))

SPLITS: dict[str, Split] = {
    split.name: split
    for split in (
        Split("train", "train", "the paper's dataset, April 2026, every start day", (SplitEntry(PAPER_DATASET),)),
        Split(
            "test",
            "test",
            f"the held-out family {TMY_FAMILY}: twelve months of three typical-year sites, every start day",
            tuple(SplitEntry(dataset.name) for dataset in family_datasets(TMY_FAMILY)),
        ),
        Split(
            "paper-early",
            "train",
            f"the paper's dataset, episodes starting on days 1-{PAPER_LAST_EARLY_DAY}",
            (SplitEntry(PAPER_DATASET, _EARLY),),
        ),
        Split(
            "paper-late",
            "test",
            f"the paper's dataset, episodes starting on days {PAPER_LAST_EARLY_DAY + 1}-{PAPER_DAYS}",
            (SplitEntry(PAPER_DATASET, _LATE),),
        ),
        Split(
            PAPER_CITIES_FAMILY,
            "test",
            f"the held-out family {PAPER_CITIES_FAMILY}: the paper's five cities, "
            f"{PAPER_CITIES_MONTHS[0]} to {PAPER_CITIES_MONTHS[-1]}, every start day (built online once)",
            tuple(SplitEntry(dataset.name) for dataset in paper_cities_datasets()),
        ),
    )
}


def get_split(name: str) -> Split:
    """The split called ``name``.

    Raises
    ------
    KeyError
        An unknown name (the message lists the known ones).
    """
    try:
        return SPLITS[name]
    except KeyError:
        raise KeyError(f"unknown split '{name}' (known: {', '.join(SPLITS)})") from None


def dataset_dir(dataset: str, build: bool = True) -> Path:
    """The directory of a dataset a split names, built on first use: offline, except a month of
    ``paper-cities`` (``paper-cities-YYYY-MM``), built online once and from the cache afterwards."""
    if dataset == PAPER_DATASET:
        from .default import default_dataset_dir

        return default_dataset_dir(build=build)
    prefix = f"{PAPER_CITIES_FAMILY}-"
    if dataset.startswith(prefix):
        return paper_cities_dataset_dir(dataset.removeprefix(prefix), build=build)
    family, _, month = dataset.rpartition("-")
    if not month.isdigit():
        raise KeyError(f"unknown dataset '{dataset}'")
    return heldout_dataset_dir(family, int(month), build=build)
