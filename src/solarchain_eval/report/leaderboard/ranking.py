"""The leaderboard's ranking: every policy of one task and protocol, ranked per setting (docs/comparing_results.md).

:func:`build_leaderboards` takes the sections of run directories, paper roots and tarballs of
either (:mod:`.inputs`), refuses inputs of different tasks or protocols unless asked to split them
and ranks each setting's policies by the mean of the task's ranked metric (:class:`BoardLayout`:
its first utility metric whose direction is ``higher``; the solar market's cumulative reward);
:func:`~.make.make_leaderboards` writes them as ``leaderboard.csv``, ``leaderboard.md``,
``leaderboard.html`` and the Pareto figure (``pareto.png``/``.svg``).

Per policy and setting a row holds the ranked metric's mean and its interquartile mean, each
with a start-day cluster-bootstrap interval; the probability of improvement over the setting's
best baseline (the best of the task's baselines by the ranked metric's mean; the solar market's
static, random and myopic), P(X > Y) + ½ P(X = Y) over *paired* episodes (the same run seed and
episode, hence the same episode seed and start day), with a start-day bootstrap interval; and
the means of the other declared metrics beside them (the solar market: the paper's board's five
safety metrics).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ...config import BenchmarkConfig
from ...evaluation.fingerprint import protocol_difference, protocol_fingerprint
from ...evaluation.settings import KNOWN_SETTINGS
from ...protocol import PAPER_EPISODES, PAPER_SEEDS
from ...tasks.base import paper_reference_of
from ...tasks.registry import DEFAULT_TASK, get_task
from ..naming import SETTINGS
from ..options import LeaderboardOptions
from ..statistics import Interval, bootstrap_iqm, bootstrap_mean, cluster_bootstrap, sample_size
from ..table_model import basis_sentence
from .grouping import check_one_protocol, check_one_task, group_by_protocol, merge_by_setting
from .layout import COLUMNS as COLUMNS
from .layout import REWARD as REWARD
from .layout import SAFETY_METRICS as SAFETY_METRICS
from .layout import BoardLayout as BoardLayout
from .layout import board_layout as board_layout
from .sections import UNKNOWN_ACCESS, LeaderboardError, Section
from .suite_inputs import SuiteBoard, SuiteSection

#: ``row_kind`` of measured rows and of the paper's published rows.
RANKED, REFERENCE = "ranked", "reference"
#: ``source`` of the paper's published rows.
REFERENCE_SOURCE = "paper (published)"
#: Columns a reference frame may give (besides ``policy``); missing ones are left empty.
REFERENCE_COLUMNS = (
    "episodes",
    f"{REWARD}_mean",
    f"{REWARD}_std",
    *(f"{metric}_mean" for metric in SAFETY_METRICS),
)


def reference_rows(setting: str) -> pd.DataFrame | None:
    """The paper's published rows of ``setting``, or None where there are none.

    The single place where the paper's published values enter a leaderboard. The frame has one
    row per policy: ``policy`` and any of :data:`REFERENCE_COLUMNS` (``cumulative_reward_mean``,
    ``cumulative_reward_std``, ``physics_violation_rate_mean``, ...). The board shows them, labelled
    :data:`REFERENCE_SOURCE` and unranked, only in sections whose protocol is the paper's
    (:func:`is_paper_protocol`). The values are the paper's stored ones
    (:mod:`~solarchain_eval.report.against_paper.paper_reference`), from the first table that prints each cell
    (the main table before the appendix); ``episodes`` is the paper's 3 × 30.
    """
    from ..against_paper.paper_reference import paper_values

    values = paper_values()
    values["column"] = values["metric"].astype(str) + "_" + values["statistic"].astype(str)
    chosen = values[
        (values["setting"] == setting)
        & (values["source"] == "table")
        & (values["level"] == "episode")
        & values["base_setting"].isna()  # not a difference between two settings
        & values["column"].isin(REFERENCE_COLUMNS)
        & ~values["policy"].astype(str).str.contains("+", regex=False)  # not the pooled learned row
    ]
    if chosen.empty:
        return None
    first = chosen.drop_duplicates(["policy", "column"], keep="first")
    frame = first.pivot(index="policy", columns="column", values="value")
    order = list(dict.fromkeys(first["policy"]))  # the paper's row order
    frame = frame.loc[order].reset_index()
    frame.columns.name = None
    frame.insert(1, "episodes", len(PAPER_SEEDS) * PAPER_EPISODES)
    return frame


def paper_protocol(setting: str) -> dict[str, Any]:
    """The fingerprint of the paper's protocol in ``setting``: the published dataset, run seeds
    20260511-13, 30 episodes each, the paper's episode-seed rule and the default configuration
    (with the setting's reward)."""
    config = BenchmarkConfig().with_updates(no_physics_penalty=KNOWN_SETTINGS[setting].no_physics_penalty)
    paper = paper_reference_of(get_task(DEFAULT_TASK))
    assert paper is not None  # the solar market's paper
    return protocol_fingerprint(
        dataset_sha256=paper.dataset_sha256,
        run_seeds=PAPER_SEEDS,
        episodes=PAPER_EPISODES,
        episode_seed_rule="paper",
        setting=setting,
        config=config,
        action_modes={},
    )


def is_paper_protocol(fingerprint: dict[str, Any]) -> bool:
    """Whether a setting's fingerprint is the paper's (its action modes aside)."""
    setting = fingerprint.get("setting")
    return setting in KNOWN_SETTINGS and protocol_difference(paper_protocol(str(setting)), fingerprint) is None


def paired_improvement(x: pd.DataFrame, y: pd.DataFrame, metric: str = REWARD, **bootstrap: Any) -> Interval:
    """P(X > Y) + ½ P(X = Y) of ``metric`` (higher is better) over paired episodes, with a start-day interval.

    Episodes pair on (run seed, episode): under one protocol they were reset with the same
    episode seed and start on the same day, so X and Y faced the same weather, demand and prices.
    The interval resamples start days (every pair of one day together).

    Raises
    ------
    LeaderboardError
        The two sets of episodes do not pair one to one on the same episode seeds.
    """
    key = ["run_seed", "episode"]
    keep = [*key, "episode_seed", "start_hour", metric]
    pairs = x[keep].merge(y[keep], on=key, suffixes=("_x", "_y"))
    mismatch = (pairs["episode_seed_x"] != pairs["episode_seed_y"]) | (pairs["start_hour_x"] != pairs["start_hour_y"])
    if len(pairs) != len(x) or len(pairs) != len(y) or mismatch.any():
        raise LeaderboardError("two policies' episodes do not pair on the same episode seeds; rank one protocol")
    a, b = pairs[f"{metric}_x"].to_numpy(float), pairs[f"{metric}_y"].to_numpy(float)
    score = (a > b).astype(float) + 0.5 * (a == b)
    return cluster_bootstrap(lambda w: (w @ score) / w.sum(axis=1), pairs["start_hour_x"], **bootstrap)


@dataclass
class BoardSection:
    """One setting of a board.

    Attributes
    ----------
    setting : str
    protocol_id : str
        The id of the setting's protocol (as a run directory of it records it).
    paper_protocol : bool
        Whether the protocol is the paper's (then the paper's rows are shown for reference).
    ranked : pandas.DataFrame
        One row per policy (``columns``), best mean of the ranked metric first.
    reference : pandas.DataFrame or None
        The paper's published rows, normalised to :data:`COLUMNS` (None when not shown).
    best_baseline : str or None
        The baseline the probability of improvement compares with (None: no baseline evaluated).
    basis : str
        The rollouts behind the rows, in one sentence.
    columns : tuple of str
        The board's columns (:meth:`BoardLayout.columns`; :data:`COLUMNS` for the solar market).
    """

    setting: str
    protocol_id: str
    paper_protocol: bool
    ranked: pd.DataFrame
    reference: pd.DataFrame | None
    best_baseline: str | None
    basis: str
    columns: tuple[str, ...] = COLUMNS

    def rows(self) -> pd.DataFrame:
        """The ranked rows, then the reference rows."""
        frames = [self.ranked] + ([self.reference] if self.reference is not None else [])
        return pd.concat(frames, ignore_index=True)[list(self.columns)]


@dataclass
class Leaderboard:
    """A board: the sections of one protocol (without its setting).

    Attributes
    ----------
    board_id : str
        The id of the protocol without its setting (``BOARD/<board_id>/`` with ``--split``).
    protocol : dict
        That protocol (the fingerprint without ``setting``; its task configuration without the
        reward switch the setting decides).
    sources : list of str
        The inputs, as given.
    sections : list of BoardSection
        One per setting, in the report's setting order.
    notes : list of str
        Duplicates dropped and other things the reader should know.
    options : LeaderboardOptions
    layout : BoardLayout
        What the board ranks and shows (its task's declarations).
    suite : SuiteBoard or None
        A suite board's suite (None for a board of runs and paper roots): its rows rank agents by
        their suite aggregates (:mod:`.suite_board`), ``board_id`` is the suite protocol id.
    """

    board_id: str
    protocol: dict[str, Any]
    sources: list[str]
    sections: list[BoardSection]
    notes: list[str] = field(default_factory=list)
    options: LeaderboardOptions = field(default_factory=LeaderboardOptions)
    layout: BoardLayout = field(default_factory=board_layout)
    suite: SuiteBoard | None = None

    def frame(self) -> pd.DataFrame:
        """Every row of every section (``leaderboard.csv``)."""
        return pd.concat([s.rows() for s in self.sections], ignore_index=True)


def _policy_row(rows: pd.DataFrame, options: LeaderboardOptions, layout: BoardLayout) -> dict[str, Any]:
    name = layout.ranked.name
    values, days = rows[name].to_numpy(float), rows["start_hour"].to_numpy()
    mean = bootstrap_mean(values, days, **options.bootstrap())
    iqm = bootstrap_iqm(values, days, **options.bootstrap())
    size = sample_size(rows)
    return {
        "episodes": size.n,
        "start_days": size.start_days,
        f"{name}_mean": mean.estimate,
        f"{name}_low": mean.low,
        f"{name}_high": mean.high,
        f"{name}_std": float(values.std(ddof=1)) if values.size > 1 else float("nan"),
        f"{name}_iqm": iqm.estimate,
        f"{name}_iqm_low": iqm.low,
        f"{name}_iqm_high": iqm.high,
        **{f"{spec.name}_mean": float(rows[spec.name].astype(float).mean()) for spec in layout.shown},
    }


def normalise_reference(frame: pd.DataFrame, setting: str, protocol_id: str, board_id: str) -> pd.DataFrame:
    """A reference frame (``policy`` and any of :data:`REFERENCE_COLUMNS`) in :data:`COLUMNS`, labelled."""
    if "policy" not in frame.columns:
        raise ValueError(f"the paper's reference rows of {setting!r} have no policy column")
    out = pd.DataFrame({"policy": frame["policy"].astype(str).to_numpy()})
    for column in COLUMNS:
        if column in REFERENCE_COLUMNS:
            out[column] = pd.to_numeric(frame[column], errors="raise").to_numpy() if column in frame else np.nan
        elif column != "policy":
            out[column] = np.nan
    out["setting"], out["source"], out["row_kind"], out["access"] = setting, REFERENCE_SOURCE, REFERENCE, ""
    out["best_baseline"], out["protocol_id"], out["board_protocol_id"] = "", protocol_id, board_id
    return out[list(COLUMNS)]


def rank_setting(
    setting: str,
    sections: Sequence[Section],
    options: LeaderboardOptions,
    board_id: str,
    references: Callable[[str], pd.DataFrame | None] | None = None,
    layout: BoardLayout | None = None,
) -> BoardSection:
    """Rank the policies of one setting (``sections`` hold each policy once; see :func:`merge_by_setting`)
    by ``layout``'s ranked metric (default: the sections' task's :func:`board_layout`)."""
    layout = layout or board_layout(sections[0].task)
    name = layout.ranked.name
    rows = pd.concat(
        [
            s.metrics.assign(
                source=s.source, access=[s.access.get(str(p), UNKNOWN_ACCESS) for p in s.metrics["policy"]]
            )
            for s in sections
        ],
        ignore_index=True,
    )
    by_policy = {str(p): group for p, group in rows.groupby("policy", sort=True)}
    table = pd.DataFrame(
        [
            {
                "policy": p,
                "access": g["access"].iloc[0],
                "source": g["source"].iloc[0],
                **_policy_row(g, options, layout),
            }
            for p, g in by_policy.items()
        ]
    )
    baselines = table[table["policy"].isin(layout.baselines)]
    best = None
    if not baselines.empty:  # the highest mean; a tie goes to the first in the task's order (static, random, myopic)
        order = baselines.assign(order=baselines["policy"].map(layout.baselines.index))
        best = str(order.sort_values([f"{name}_mean", "order"], ascending=[False, True]).iloc[0]["policy"])
    improvements = [
        paired_improvement(by_policy[p], by_policy[best], name, **options.bootstrap())
        if best
        else Interval(*[np.nan] * 3)
        for p in table["policy"]
    ]
    table["best_baseline"] = best or ""
    table["p_improvement"] = [i.estimate for i in improvements]
    table["p_improvement_low"] = [i.low for i in improvements]
    table["p_improvement_high"] = [i.high for i in improvements]
    # Best first: descending mean, ties by name so the order never depends on the inputs' order.
    table = table.sort_values([f"{name}_mean", "policy"], ascending=[False, True], kind="stable")
    table = table.reset_index(drop=True)
    table["rank"] = np.arange(1, len(table) + 1)
    protocol = sections[0].protocol
    table["setting"], table["row_kind"] = setting, RANKED
    table["protocol_id"], table["board_protocol_id"] = sections[0].protocol_id, board_id
    paper = layout.paper is not None and is_paper_protocol(protocol)
    reference = None
    if paper:
        published = (references or reference_rows)(setting)
        if published is not None and not published.empty:
            reference = normalise_reference(published, setting, sections[0].protocol_id, board_id)
    basis = basis_sentence([sample_size(g) for g in by_policy.values()], "rollouts")
    columns = layout.columns()
    ranked = table[list(columns)]
    return BoardSection(setting, sections[0].protocol_id, paper, ranked, reference, best, basis, columns)


def build_leaderboard(
    sections: Sequence[Section],
    options: LeaderboardOptions | None = None,
    references: Callable[[str], pd.DataFrame | None] | None = None,
) -> Leaderboard:
    """One board from ``sections`` (see :func:`~.inputs.open_inputs`).

    Parameters
    ----------
    sections : sequence of Section
    options : LeaderboardOptions, optional
    references : callable, optional
        ``setting -> DataFrame | None``: the published rows (default :func:`reference_rows`).

    Raises
    ------
    LeaderboardError
        The sections are of different tasks, or do not share one protocol apart from their
        setting (one line naming the field and two inputs), or one policy name holds different
        results in two inputs.
    """
    options = options or LeaderboardOptions()
    if not sections:
        raise LeaderboardError("no rows to rank")
    suite = next((s for s in sections if isinstance(s, SuiteSection)), None)
    if suite is not None:  # its rows are normalised suite scores: suite_board.build_boards ranks them
        raise LeaderboardError(f"{suite.where} is a suite root; rank it with suite_board.build_boards")
    check_one_task(sections)
    check_one_protocol(sections)
    layout = board_layout(sections[0].task)
    by_setting, notes = merge_by_setting(sections)
    board_id = sections[0].board_id
    order = [s for s in SETTINGS if s in by_setting] + sorted(set(by_setting) - set(SETTINGS))
    ranked = [rank_setting(s, by_setting[s], options, board_id, references, layout) for s in order]
    sources = list(dict.fromkeys(s.source for s in sections))
    return Leaderboard(board_id, dict(sections[0].board_protocol), sources, ranked, notes, options, layout)


def build_leaderboards(
    sections: Sequence[Section],
    options: LeaderboardOptions | None = None,
    references: Callable[[str], pd.DataFrame | None] | None = None,
) -> list[Leaderboard]:
    """One board per task and protocol with ``options.split``, else exactly one (or a refusal)."""
    options = options or LeaderboardOptions()
    if not options.split:
        return [build_leaderboard(sections, options, references)]
    return [build_leaderboard(group, options, references) for group in group_by_protocol(sections).values()]
