"""A task's dataset builder: an optional capability (its ``dataset`` attribute).

``solarchain-eval data``, ``sweep`` (its dataset axes) and ``bench-scale`` build, check and list
datasets. They reach a market's dataset pipeline only through the builder its task supplies as
``task.dataset``, read with :func:`dataset_of`; a task without one has no dataset commands (a
one-line error). The interface has two layers:

- :class:`ScenarioDatasetBuilder`, what every builder has and all ``sweep`` needs: build
  parameters (a seed, a date range, and a false-data scenario of rate, pattern and severity) in,
  a directory of files and a manifest out (:meth:`ScenarioDatasetBuilder.build_point`), byte for
  byte the same for the same parameters. The supply-chain market's builder is one.
- :class:`DatasetBuilder`, the full builder that ``data`` and ``bench-scale`` use, which adds what
  only a weather-driven market has: cities, nodes per city, weather sources and files, named
  splits and shipped families. The solar market's builder is one. A market without weather does
  not fake these members; it supplies the smaller protocol.

This module imports nothing from the package beyond the bottom layer, so every wing may use it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from ..common.errors import OptionsError


@dataclass(frozen=True)
class BuildDefaults:
    """The build parameters a dataset takes when none are given.

    Attributes
    ----------
    seed : int
        Seed of the build's random stream.
    start, end : str
        First day and the day after the last one (local time), ``YYYY-MM-DD``.
    timezone : str or None
        IANA time zone of the dataset's hours (None: a builder whose records are whole days).
    nodes_per_city : int or None
        Producing nodes per city (None: a builder without cities and nodes).
    """

    seed: int
    start: str
    end: str
    timezone: str | None
    nodes_per_city: int | None


@dataclass(frozen=True)
class FalseDataKnobs:
    """The false-data scenario a builder injects: its patterns and defaults.

    Attributes
    ----------
    pattern_lines : mapping of str to str
        Each pattern's name and its line of help, in order; ``{burst_hours}`` in a line stands for
        where the burst length is set.
    default_pattern : str
        The pattern of a build that names none.
    default_rate : float
        The fraction of records injected by default, in [0, 1].
    default_burst_hours : int
        Hours per clustered burst by default.
    """

    pattern_lines: Mapping[str, str]
    default_pattern: str
    default_rate: float
    default_burst_hours: int

    @property
    def patterns(self) -> tuple[str, ...]:
        """The pattern names, in order."""
        return tuple(self.pattern_lines)

    def pattern_help(self, burst_hours: str = "burst_hours") -> str:
        """Every pattern as ``NAME: line``, in one paragraph; ``burst_hours`` names where the burst
        length is set (the command line passes its option)."""
        return " ".join(f"{name}: {line.format(burst_hours=burst_hours)}" for name, line in self.pattern_lines.items())


@dataclass(frozen=True)
class SplitSummary:
    """One named split as ``data splits`` lists it.

    Attributes
    ----------
    name, role, description : str
        The split, what it is for (``train``/``test``) and what it holds.
    datasets : tuple of str
        Its datasets, in order.
    start_days : tuple of int or None
        The days its episodes may start on (None: every day).
    """

    name: str
    role: str
    description: str
    datasets: tuple[str, ...]
    start_days: tuple[int, ...] | None


@dataclass(frozen=True)
class FamilyMember:
    """One dataset of a shipped family (``data build-family``): its directory name and dates,
    ``handle``, the builder's own description of it (generic code passes it back unread),
    ``pinned``, whether its files are checked against sha256s shipped with the package, and
    ``weather``, its weather and licence in a few words."""

    name: str
    start: str
    end: str
    handle: Any = None
    pinned: bool = True
    weather: str = ""


#: ``progress(stage, done, total)`` of a build; the ``"generation"`` stage counts nodes.
BuildProgress = Callable[[str, int, int], None]

#: The build parameters every builder takes (the keys of a sweep's ``dataset`` section and axes).
SCENARIO_PARAMETERS = ("seed", "start", "end", "fdia_rate", "fdia_pattern", "fdia_severity", "fdia_burst_hours")


@runtime_checkable
class ScenarioDatasetBuilder(Protocol):
    """What every task's dataset builder supplies: a build from parameters (see the module docstring).

    Attributes
    ----------
    files : tuple of str
        The data files of a dataset directory, beside its manifest (``manifest``).
    manifest : str
        The file written last, which marks a complete build.
    defaults : BuildDefaults
        The build parameters of a build that gives none.
    false_data : FalseDataKnobs
        The false-data scenario's patterns and defaults.
    parameters : tuple of str
        The build parameters :meth:`build_point` reads: :data:`SCENARIO_PARAMETERS` and the
        builder's own (the solar market's ``cities``, ``nodes_per_city``, ``timezone``,
        ``weather_cache``). A sweep refuses a dataset key or axis that is not among them.
    """

    files: tuple[str, ...]
    manifest: str
    defaults: BuildDefaults
    false_data: FalseDataKnobs
    parameters: tuple[str, ...]

    def scenario(self, rate: float, severity: str | None, pattern: str, burst_hours: int) -> Any:
        """The false-data scenario (``severity`` ``"LO:HI"`` or None); ``ValueError`` names the bad knob."""
        ...

    def build_point(self, out: Path, parameters: Mapping[str, Any]) -> dict[str, Any]:
        """Build the dataset of ``parameters`` (the :attr:`parameters`' values; paths absolute) into
        ``out``, the manifest written last; returns the manifest. ``ValueError``: a bad value."""
        ...

    def check(self, data_dir: Path) -> tuple[tuple[str, str], ...]:
        """Validate the dataset in ``data_dir`` (a one-line error naming the file otherwise);
        returns its summary as (what, value) rows."""
        ...


@runtime_checkable
class DatasetBuilder(ScenarioDatasetBuilder, Protocol):
    """The full builder ``data`` and ``bench-scale`` use: :class:`ScenarioDatasetBuilder` and a
    weather-driven market's cities, weather, splits and families (see the module docstring).

    Cities, weather and scenarios are the builder's own objects: generic code passes on what the
    builder returned and reads nothing inside them.

    Attributes
    ----------
    node_records_file : str
        The file with one row per node and hour (its rows measure a build's size).
    weather_sources : tuple of str
        The named weather sources (``data build --weather``).
    downloaded_weather_sources : tuple of str
        Those of them that download, city by city (the command line shows a progress bar).
    paper_weather_sha256 : str or None
        sha256 of the paper's weather payload, when the task has one (a build names it).
    split_rule : str
        How the splits are to be used (one line).
    families : tuple of str
        The shipped dataset families (``data build-family``).
    """

    node_records_file: str
    weather_sources: tuple[str, ...]
    downloaded_weather_sources: tuple[str, ...]
    paper_weather_sha256: str | None
    split_rule: str
    families: tuple[str, ...]

    def cities(self, specs: Sequence[str] | int | None) -> tuple[Any, ...]:
        """The cities of a build: None the default ones, a number that many synthetic ones,
        ``NAME:LAT:LON`` strings those cities. ``ValueError``: a bad spec or a shared node-id prefix."""
        ...

    def choose_weather(self, cities: Sequence[Any], start: str, end: str, **options: Any) -> Any:
        """The weather of a build (keywords: ``seed``, ``timezone``, ``weather_cache``, ``source``,
        ``open_meteo_url``, ``refresh``, ``retries``, ``on_city``, ``notify``)."""
        ...

    def read_weather_files(self, specs: Sequence[str]) -> tuple[Any, str]:
        """Read ``[CITY=]FILE`` weather files; returns them and the first file's time zone."""
        ...

    def weather_from_files(self, read: Any, timezone: str, start: str, end: str) -> tuple[tuple[Any, ...], Any]:
        """The cities (at the files' sites) and the weather of a build from :meth:`read_weather_files`'s files."""
        ...

    def build(
        self,
        weather: Any,
        out: Path,
        *,
        cities: Sequence[Any],
        seed: int,
        start: str,
        end: str,
        nodes_per_city: int,
        timezone: str,
        scenario: Any = None,
        progress: BuildProgress | None = None,
    ) -> dict[str, Any]:
        """Build a dataset into ``out`` (the manifest written last); returns the manifest."""
        ...

    def is_published(self, file_sha256: Mapping[str, str]) -> bool:
        """Whether the files' sha256 (name -> digest) are the paper's published dataset's."""
        ...

    def splits(self) -> tuple[SplitSummary, ...]:
        """The named splits, in order."""
        ...

    def family(self, family: str, months: Sequence[str | int] | None) -> tuple[FamilyMember, ...]:
        """The members of a shipped family (``months`` as the family names them; None: its default
        ones); an error names an unknown family or month."""
        ...

    def build_family_member(self, member: FamilyMember, out: Path, *, replace: bool, **options: Any) -> dict[str, Any]:
        """Build ``member`` into ``out`` (if pinned, only when it matches its shipped checksums);
        returns its manifest. ``options``: those of :meth:`choose_weather` for a family whose
        weather is downloaded (``open_meteo_url``, ``retries``, ``notify``)."""
        ...


class NoDatasetBuilderError(OptionsError, ValueError):
    """A task without a dataset builder was asked to build or check a dataset."""


def dataset_of(task: Any) -> DatasetBuilder:
    """``task``'s dataset builder (its optional ``dataset`` attribute). It may be a
    :class:`ScenarioDatasetBuilder` only (a market without weather); ``data`` and ``bench-scale``
    use the solar market's, which is a full :class:`DatasetBuilder`.

    Raises
    ------
    NoDatasetBuilderError
        The task has none.
    """
    builder = getattr(task, "dataset", None)
    if builder is None:
        raise NoDatasetBuilderError(f"task {getattr(task, 'name', task)!r} has no dataset builder")
    return builder


def has_dataset_builder(task: Any) -> bool:
    """Whether ``task`` has a dataset builder."""
    return getattr(task, "dataset", None) is not None
