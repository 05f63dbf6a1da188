"""Suite boards: agents ranked by their suite aggregate (docs/suites.md#ranking-and-reporting-suite-runs).

A suite root (:class:`~.suite_inputs.SuiteSection`) is ranked on a board of its own suite protocol
id: per policy, the IQM of its normalised scores over every entry and episode with its
stratified-bootstrap interval, and beside it the mean, the median and the optimality gap with
theirs, all computed by :func:`~solarchain_eval.evaluation.suite_stats.aggregate_table` (rliable's
definitions, the suite's own bootstrap seed), and P(X > Y) over the suite's upper reference
baseline (:func:`~solarchain_eval.evaluation.suite_stats.probability_of_improvement`). Policies are
ranked by IQM, best first.

:func:`build_boards` is the leaderboard's one entry to ranking (:func:`~.make.make_leaderboards`):
boards of runs and paper roots as :func:`~.ranking.build_leaderboards` makes them, suite boards
beside them. A suite board never holds another suite protocol (another split, other datasets,
seeds or episodes) nor a run directory or paper root: without ``--split`` a mix is refused in one
line naming two inputs, with it each goes to its own board and one line says which were kept apart.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import pandas as pd

from ...evaluation.suite_run import SuiteScoreError, matrices
from ...evaluation.suite_stats import AGGREGATE_NAMES, aggregate_table, probability_of_improvement
from ..options import LeaderboardOptions
from .columns import DisplayColumn, number, rank_cell, reference_interval, shown_policy
from .grouping import describe_difference, merge_by_setting
from .layout import board_layout
from .ranking import RANKED, BoardSection, Leaderboard, build_leaderboards
from .sections import LeaderboardError, Section
from .suite_inputs import SuiteSection

#: The columns of a suite board's ``leaderboard.csv``, in order (the aggregates as ``suite_metadata.json`` names them).
SUITE_COLUMNS = (
    "setting",
    "rank",
    "policy",
    "access",
    "source",
    "row_kind",
    "entries",
    "episodes",
    *(f"{name}{part}" for name in AGGREGATE_NAMES for part in ("", "_low", "_high")),
    "best_baseline",
    "p_improvement",
    "suite",
    "splits",
    "protocol_id",
    "board_protocol_id",
)
#: The performance profile's file stem on a suite board.
PROFILE = "performance_profile"
_HEADERS = {"iqm": "IQM", "mean": "Mean", "median": "Median", "optimality_gap": "Optimality gap"}


def _describe(section: SuiteSection) -> str:
    return f"{section.where} (split {', '.join(section.splits)}, suite protocol {section.protocol_id})"


def check_one_suite_protocol(sections: Sequence[SuiteSection]) -> None:
    """Refuse suite roots of different suite protocols: different splits first, else the first differing field.

    Raises
    ------
    LeaderboardError
        One line naming two inputs and what differs.
    """
    first = sections[0]
    for other in sections[1:]:
        if other.splits != first.splits:
            raise LeaderboardError.about(
                "{a} and {b} are suites of different splits; a board never mixes splits ({opt_split} writes one "
                "board per suite protocol)",
                a=_describe(first),
                b=_describe(other),
            )
        if other.board_id != first.board_id:
            field = next(
                k
                for k in sorted(set(first.protocol) | set(other.protocol))
                if first.protocol.get(k) != other.protocol.get(k)
            )
            raise LeaderboardError.about(
                "{a} and {b} were evaluated under different suite protocols: {difference} differs; a board ranks "
                "one protocol ({opt_split} writes one board per suite protocol)",
                a=_describe(first),
                b=_describe(other),
                difference=describe_difference(field, first.protocol, other.protocol),
            )


def build_suite_leaderboard(sections: Sequence[SuiteSection], options: LeaderboardOptions | None = None) -> Leaderboard:
    """One suite board from suite roots of one suite protocol (each policy once; see :func:`~.grouping.merge_by_setting`).

    Raises
    ------
    LeaderboardError
        The roots are of different suite protocols, a policy name holds different scores in two
        roots, or the policies' episodes differ.
    """
    options = options or LeaderboardOptions()
    if not sections:
        raise LeaderboardError("no suite root to rank")
    check_one_suite_protocol(sections)
    first = sections[0]
    assert first.board is not None  # every SuiteSection is made with its board
    by_setting, notes = merge_by_setting(sections)
    kept = by_setting[first.setting]
    scores = pd.concat([s.metrics for s in kept], ignore_index=True)
    suite = replace(first.board, scores=scores)
    owner = {str(p): s for s in kept for p in s.metrics["policy"].unique()}
    try:
        per_policy = matrices(scores)
    except SuiteScoreError as error:
        raise LeaderboardError(f"{first.where}: {error}") from None
    table = pd.DataFrame(aggregate_table(per_policy, reps=options.n_resamples, seed=suite.bootstrap_seed))
    high = suite.reference[1]
    table["best_baseline"] = high if high in per_policy else ""
    table["p_improvement"] = [
        probability_of_improvement(per_policy[p], per_policy[high]) if high in per_policy else float("nan")
        for p in table["policy"]
    ]
    table["access"] = [owner[p].access.get(p, "unknown") for p in table["policy"]]
    table["source"] = [owner[p].source for p in table["policy"]]
    table["entries"] = [per_policy[p].shape[1] for p in table["policy"]]
    table["episodes"] = [per_policy[p].shape[0] for p in table["policy"]]
    # Best first: descending IQM, ties by name so the order never depends on the inputs' order.
    table = table.sort_values(["iqm", "policy"], ascending=[False, True], kind="stable").reset_index(drop=True)
    table["rank"] = range(1, len(table) + 1)
    table["setting"], table["row_kind"], table["suite"] = first.setting, RANKED, suite.suite
    table["splits"] = ",".join(suite.splits)
    table["protocol_id"] = table["board_protocol_id"] = first.protocol_id
    episodes = int(table["episodes"].iloc[0])
    basis = (
        f"Per policy: {len(suite.entries)} entries × {episodes} episodes (run seeds × episodes), "
        f"{len(suite.entries) * episodes} normalised scores."
    )
    section = BoardSection(
        first.setting,
        first.protocol_id,
        False,
        table[list(SUITE_COLUMNS)],
        None,
        table["best_baseline"].iloc[0] or None,
        basis,
        SUITE_COLUMNS,
    )
    sources = list(dict.fromkeys(s.source for s in sections))
    layout = board_layout(first.task)
    return Leaderboard(first.board_id, dict(first.protocol), sources, [section], notes, options, layout, suite)


def _kept_apart(plain: Sequence[Section], groups: dict[str, list[SuiteSection]]) -> str:
    """One line: which inputs went to which board."""
    parts = [
        f"suite {g[0].board.suite if g[0].board else '?'} (split {', '.join(g[0].splits)}, suite protocol {key}): "
        + ", ".join(dict.fromkeys(s.source for s in g))
        for key, g in groups.items()
    ]
    if plain:
        parts.append("runs and paper roots: " + ", ".join(dict.fromkeys(s.source for s in plain)))
    return "kept apart, one board each: " + "; ".join(parts)


def build_boards(
    sections: Sequence[Section],
    options: LeaderboardOptions | None = None,
    references: Callable[[str], pd.DataFrame | None] | None = None,
) -> tuple[list[Leaderboard], list[str]]:
    """Every board of ``sections`` and the notes on how they were split (see the module docstring).

    Returns
    -------
    (list of Leaderboard, list of str)
        The boards of runs and paper roots (:func:`~.ranking.build_leaderboards`), then one per
        suite protocol; and the line saying which inputs were kept apart (empty when none were).

    Raises
    ------
    LeaderboardError
        Without ``options.split``: suite roots beside runs or paper roots, or suite roots of
        different suite protocols (one line naming two inputs).
    """
    options = options or LeaderboardOptions()
    suites = [s for s in sections if isinstance(s, SuiteSection)]
    plain = [s for s in sections if not isinstance(s, SuiteSection)]
    if not suites:
        return build_leaderboards(plain, options, references), []
    if not options.split and plain:
        raise LeaderboardError.about(
            "{a} is a suite root and {b} is not; a board never ranks suite results beside single-task runs "
            "({opt_split} writes one board each)",
            a=_describe(suites[0]),
            b=plain[0].where,
        )
    groups: dict[str, list[SuiteSection]] = {}
    for section in suites:
        groups.setdefault(section.board_id, []).append(section)
    if not options.split:
        check_one_suite_protocol(suites)
    boards = build_leaderboards(plain, options, references) if plain else []
    boards += [build_suite_leaderboard(group, options) for group in groups.values()]
    if len(groups) + bool(plain) < 2:
        return boards, []
    line = _kept_apart(plain, groups)
    for board in boards:
        if board.suite is not None:
            board.notes.append(line)
    return boards, [line]


def suite_display_columns(board: Leaderboard) -> list[DisplayColumn]:
    """The printed columns of a suite board's table."""
    high = board.suite.reference[1] if board.suite else "the upper reference"
    aggregates = [
        DisplayColumn(
            f"{_HEADERS[name]} [95% CI]",
            name,
            True,
            "ascending" if name == "optimality_gap" else "descending",
            reference_interval(name, 3),
        )
        for name in AGGREGATE_NAMES
    ]
    return [
        DisplayColumn("Rank", "rank", True, "ascending", rank_cell),
        DisplayColumn("Policy", "policy", False, "ascending", lambda r: shown_policy(board.layout, str(r["policy"]))),
        DisplayColumn("Access", "access", False, "ascending", lambda r: str(r["access"]) or "–"),
        DisplayColumn("Source", "source", False, "ascending", lambda r: str(r["source"])),
        DisplayColumn("Episodes per entry", "episodes", True, "descending", number("episodes", 0)),
        *aggregates,
        DisplayColumn(f"P(> {high})", "p_improvement", True, "descending", number("p_improvement", 3)),
    ]


def suite_protocol_lines(board: Leaderboard) -> list[tuple[str, str]]:
    """The suite board's header lines: suite, splits, suite protocol id, entries and what it hashes."""
    suite = board.suite
    assert suite is not None
    protocol = board.protocol
    return [
        ("Suite", suite.suite),
        ("Splits", ", ".join(suite.splits)),
        ("Suite protocol id", board.board_id),
        ("Entries", ", ".join(suite.entries)),
        ("Entries' run protocol ids", ", ".join(protocol.get("protocol_ids", []))),
        ("Score", ", ".join(protocol.get("score", []))),
        ("Normalisation", str(protocol.get("normalisation", ""))),
    ]


def suite_reading(board: Leaderboard) -> list[str]:
    """How to read a suite board, in a few sentences."""
    suite = board.suite
    assert suite is not None
    low, high = suite.reference
    return [
        f"Scores are normalised per entry on the entry's own baselines: 0 is {low}'s mean score, 1 is {high}'s.",
        "Policies are ranked by the IQM (interquartile mean, rliable's) of their normalised scores over every "
        "entry and episode; mean and median are of the per-entry means; the optimality gap is how far the scores "
        "fall short of 1 (lower is better).",
        f"Intervals are 95 % percentile intervals of a stratified bootstrap ({board.options.n_resamples} "
        f"resamples, seed {suite.bootstrap_seed}): every entry's episodes are resampled separately.",
        f"P(> {high}) is P(X > Y) per entry (ties count half), averaged over entries, with Y = {high}.",
        "Only suite roots of this suite protocol id are on this board: never another split, never single-task runs.",
    ]


def suite_profile_figure(board: Leaderboard) -> dict[str, bytes]:
    """The board's performance profile as PNG and SVG bytes (``performance_profile.png``/``.svg``)."""
    from ...evaluation.suite_stats import draw_performance_profile
    from ..figure_style import figure_bytes, new_figure, policy_colour

    assert board.suite is not None and board.suite.scores is not None
    per_policy = matrices(board.suite.scores)
    colours = {p: policy_colour(p, list(per_policy)) for p in per_policy}
    with new_figure(figsize=(6.0, 4.0)) as (figure, axes):
        draw_performance_profile(axes[0, 0], per_policy, colours)
        axes[0, 0].set_title(f"suite {board.suite.suite}: performance profile")
        return figure_bytes(figure)
