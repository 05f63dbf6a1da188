"""The inputs of a leaderboard: run directories, paper roots, suite roots and tarballs of a run
directory or paper root, opened into sections (:mod:`.sections`; a suite root's:
:mod:`.suite_inputs`).

A tarball is checked before anything is written (:mod:`.tarballs`: size and member limits, and a
file its metadata does not vouch for is refused), unpacked into a temporary folder and read as
the folder it holds. The names of :mod:`.sections` stay importable here.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path

from ..suite_loading import is_suite_root
from .sections import LEGACY_ACCESS as LEGACY_ACCESS
from .sections import LEGACY_ENV_ID as LEGACY_ENV_ID
from .sections import LEGACY_PROTOCOL_KEYS as LEGACY_PROTOCOL_KEYS
from .sections import UNKNOWN_ACCESS as UNKNOWN_ACCESS
from .sections import LeaderboardError as LeaderboardError
from .sections import Section as Section
from .sections import board_fingerprint as board_fingerprint
from .sections import data_sections as data_sections
from .sections import read_input as read_input
from .sections import rule_name as rule_name
from .sections import run_protocol as run_protocol
from .suite_inputs import read_suite_input
from .tarballs import TarballLimits, TarballRefused, unpack_tarball

#: Names of inputs read as tarballs of a run directory, a paper root or a suite root.
TARBALL_SUFFIXES = (".tar", ".tar.gz", ".tgz", ".tar.bz2", ".tbz2", ".tar.xz", ".txz")


def _is_tarball(path: Path) -> bool:
    return path.is_file() and path.name.lower().endswith(TARBALL_SUFFIXES)


def _unpack(tarball: Path, into: Path, limits: TarballLimits | None) -> Path:
    """Check ``tarball`` before writing anything (:mod:`.tarballs`: limits, links, files nothing
    vouches for), extract it and return the run or paper root inside it."""
    try:
        return unpack_tarball(tarball, into, limits)
    except TarballRefused as error:
        raise LeaderboardError(str(error)) from None


def check_out_outside_inputs(paths: Sequence[Path | str], out: Path | str) -> None:
    """Refuse a board folder inside an input folder: its files would change the run it ranks."""
    target = Path(out).resolve()
    for given in paths:
        path = Path(given)
        if path.is_dir() and target.is_relative_to(path.resolve()):
            raise LeaderboardError.about(
                "{opt_out} {out} lies inside the input {given}; its files would change the run it ranks "
                "(write the board to a folder outside every input)",
                out=out,
                given=given,
            )


@contextmanager
def open_inputs(paths: Sequence[Path | str], limits: TarballLimits | None = None) -> Iterator[list[Section]]:
    """Every section of every input (tarballs, within ``limits``, unpacked into a temporary folder
    removed on exit; a suite root gives one :class:`~.suite_inputs.SuiteSection`).

    Raises
    ------
    LeaderboardError
        No input, an input that is neither a folder nor a tarball, or one that cannot be ranked.
    """
    if not paths:
        raise LeaderboardError("no run directory, paper root, suite root or tarball given")
    with ExitStack() as stack:
        sections: list[Section] = []
        for given in paths:
            path = Path(given)
            if _is_tarball(path):
                scratch = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="solarchain-board-")))
                unpacked = _unpack(path, scratch, limits)
                if is_suite_root(unpacked):
                    sections.append(read_suite_input(unpacked, source=str(given)))
                else:
                    sections += read_input(unpacked, source=str(given))
            elif path.is_dir() and is_suite_root(path):
                sections.append(read_suite_input(path, source=str(given)))
            elif path.is_dir():
                sections += read_input(path, source=str(given))
            else:
                raise LeaderboardError(f"{given}: not a run directory, a paper root, a suite root or a tarball of one")
        yield sections
