"""A suite root as a leaderboard input (docs/suites.md#ranking-and-reporting-suite-runs).

A suite root (``evaluate --suite NAME --out ROOT``) is one :class:`SuiteSection`: its rows are the
root's normalised scores (``suite_scores.csv``: entry, policy, run seed, episode), its protocol the
suite protocol (the entries' run protocol ids, the score, the normalisation and the splits), so
two suite roots share a board only when their suite protocol ids are equal, and a suite root never
shares one with a run directory or paper root. The root is read and verified by
:func:`~solarchain_eval.report.suite_loading.load_suite_data`, and each entry's run is held to the
rules of any other input (its protocol, every rollout its protocol promises: :func:`~.sections.data_sections`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from ..suite_loading import SuiteData, load_suite_data
from .sections import UNKNOWN_ACCESS, Section, data_sections


@dataclass(frozen=True)
class SuiteBoard:
    """What a suite board ranks (:attr:`~.ranking.Leaderboard.suite`).

    Attributes
    ----------
    suite : str
    splits : tuple of str
        The splits of the suite's entries (a board holds one suite protocol, hence one set of splits).
    reference : tuple of (str, str)
        The baselines a normalised score of 0 and 1 stand for.
    entries : tuple of str
        The entries, in the suite's order.
    bootstrap_seed : int
        The seed of the stratified bootstrap (the suite's own, from ``suite_metadata.json``).
    scores : pandas.DataFrame or None
        On a board: the ranked scores of every root (each policy once), as ``suite_scores.csv`` holds them.
    """

    suite: str
    splits: tuple[str, ...]
    reference: tuple[str, str]
    entries: tuple[str, ...]
    bootstrap_seed: int
    scores: pd.DataFrame | None = field(default=None, compare=False, repr=False)


@dataclass
class SuiteSection(Section):
    """One suite root's scores: a :class:`~.sections.Section` whose ``metrics`` are ``suite_scores.csv``'s
    rows and whose ``protocol`` (and ``board_protocol``) is the suite protocol.

    Attributes
    ----------
    board : SuiteBoard or None
        The suite, its splits, reference baselines, entries and bootstrap seed.
    """

    board: SuiteBoard | None = field(default=None)

    @property
    def splits(self) -> tuple[str, ...]:
        """The splits of the suite's entries."""
        return self.board.splits if self.board is not None else ()


def suite_section(data: SuiteData, source: str) -> SuiteSection:
    """The section of a verified suite root (each entry's run checked as a leaderboard input).

    Raises
    ------
    LeaderboardError
        An entry's run lacks rollouts its protocol promises, or has no protocol to compare.
    """
    access: dict[str, str] = {}
    for entry in data.entries:
        run = data.runs[entry["name"]]
        for section in data_sections(run, f"{source}/{entry['name']}"):
            access.update(section.access)
    policies = sorted(set(data.scores["policy"].astype(str)))
    board = SuiteBoard(
        data.suite, data.splits, data.reference, tuple(e["name"] for e in data.entries), data.bootstrap_seed
    )
    return SuiteSection(
        source=source,
        where=f"{source} [suite {data.suite}]",
        setting=data.setting,
        protocol=dict(data.protocol),
        board_protocol=dict(data.protocol),
        metrics=data.scores,
        access={p: access.get(p, UNKNOWN_ACCESS) for p in policies},
        task=str(data.entries[0]["task"]),
        board=board,
    )


def read_suite_input(path: Path, source: str | None = None) -> SuiteSection:
    """The section of the suite root ``path``, read and verified.

    Raises
    ------
    ReportDataError
        A file of the root or of an entry's run is missing, malformed or not vouched for.
    LeaderboardError
        An entry's run cannot be ranked (see :func:`suite_section`).
    """
    path = Path(path)
    return suite_section(load_suite_data(path), source or str(path))
