"""Make the boards: read the inputs, rank them and write every board's files.

``make_leaderboards(paths, out)`` is the leaderboard's entry point (``solarchain-eval leaderboard``):
it opens the inputs (:mod:`.inputs`), ranks them (:mod:`.ranking`), renders the files
(:mod:`.render`) and only then writes them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from ...common.atomic_files import atomic_write_bytes
from ..options import LeaderboardOptions
from .inputs import check_out_outside_inputs, open_inputs
from .ranking import Leaderboard
from .render import render_files
from .suite_board import build_boards
from .tarballs import TarballLimits


@dataclass
class LeaderboardOutcome:
    """What :func:`make_leaderboards` wrote: the boards, the files (relative path -> path) and the notes
    on how the inputs were split into boards (the line naming the inputs kept apart; empty when none were)."""

    out_dir: Path
    boards: list[Leaderboard]
    files: dict[str, Path]
    notes: list[str] = field(default_factory=list)


def make_leaderboards(
    paths: Sequence[Path | str],
    out: Path | str,
    options: LeaderboardOptions | None = None,
    references: Callable[[str], pd.DataFrame | None] | None = None,
) -> LeaderboardOutcome:
    """Read ``paths``, rank them and write the board(s) into ``out``.

    Every file is rendered before the first is written, and each is written atomically: a
    refusal or an error leaves ``out`` as it was. With ``options.split`` each protocol's board
    goes to ``out/<board id>/``. A suite root (``evaluate --suite``) is ranked on a board of its
    suite protocol (:mod:`.suite_board`), never beside runs, paper roots or another split.

    Raises
    ------
    LeaderboardError, ReportDataError
        Inputs that cannot be ranked together (see :func:`~.ranking.build_leaderboard`) or read, a
        tarball past ``options``' limits, or ``out`` inside an input.
    """
    options = options or LeaderboardOptions()
    check_out_outside_inputs(paths, out)
    limits = TarballLimits(options.max_unpacked_mb, options.max_members)
    with open_inputs(paths, limits) as sections:
        boards, notes = build_boards(sections, options, references)
    rendered: dict[str, bytes] = {}
    for board in boards:
        prefix = f"{board.board_id}/" if options.split else ""
        rendered.update({prefix + name: data for name, data in render_files(board, options.formats).items()})
    out = Path(out)
    files = {name: atomic_write_bytes(out / name, data) for name, data in rendered.items()}
    return LeaderboardOutcome(out, boards, files, notes)
