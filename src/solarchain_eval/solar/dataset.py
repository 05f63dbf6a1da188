"""The solar market's dataset builder: the :class:`~solarchain_eval.tasks.dataset.DatasetBuilder`
that ``data``, ``sweep`` and ``bench-scale`` reach through the task (``SOLAR_TASK.dataset``).

It wraps the dataset pipeline of :mod:`solarchain_eval.data`: the paper's cities and defaults
(:mod:`~solarchain_eval.data.cities`), the false-data scenario (:mod:`~solarchain_eval.data.fdia`),
the weather sources (:mod:`~solarchain_eval.data.sources`, standard weather files), the build
(:mod:`~solarchain_eval.data.build`), the validating loader, the named splits and the held-out
family. The heavy modules are imported when first used.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..data.cities import (
    DEFAULT_END,
    DEFAULT_NODES_PER_CITY,
    DEFAULT_SEED,
    DEFAULT_START,
    DEFAULT_TIMEZONE,
    PAPER_CITIES,
    City,
    check_unique_prefixes,
    parse_city,
    synthetic_cities,
)
from ..data.fdia import (
    DEFAULT_BURST_HOURS,
    DEFAULT_FDIA_PATTERN,
    FDIA_FRACTION,
    FDIA_PATTERN_LINES,
    FdiaScenario,
    scenario_from_knobs,
)
from ..data.files import DATASET_FILES, GENERATION_FILE, MANIFEST_FILE
from ..data.heldout import MONTHS, TMY_FAMILY, build_checked, heldout_dataset
from ..data.paper_cities import PAPER_CITIES_FAMILY, PAPER_CITIES_MONTHS, build_online
from ..data.paper_cities import family_datasets as paper_cities_datasets
from ..data.published import PAPER_WEATHER_SHA256, matches_published
from ..data.sources import WeatherSource, choose_weather
from ..data.splits import SPLIT_RULE, SPLITS
from ..data.weather import WeatherError
from ..data.weather_files import FileWeather, etc_zone, parse_weather_file_spec, read_weather_file, weather_from_files
from ..tasks.dataset import (
    SCENARIO_PARAMETERS,
    BuildDefaults,
    BuildProgress,
    FalseDataKnobs,
    FamilyMember,
    SplitSummary,
)

#: The solar market's build defaults: the paper's seed, April 2026, Asia/Shanghai, ten nodes per city.
SOLAR_BUILD_DEFAULTS = BuildDefaults(DEFAULT_SEED, DEFAULT_START, DEFAULT_END, DEFAULT_TIMEZONE, DEFAULT_NODES_PER_CITY)
#: The FDIA scenario's patterns and defaults (data/fdia.py).
SOLAR_FALSE_DATA = FalseDataKnobs(FDIA_PATTERN_LINES, DEFAULT_FDIA_PATTERN, FDIA_FRACTION, DEFAULT_BURST_HOURS)


@dataclass(frozen=True)
class SolarDataset:
    """The solar market's dataset builder (see the module docstring); use :data:`SOLAR_DATASET`."""

    files: tuple[str, ...] = DATASET_FILES
    manifest: str = MANIFEST_FILE
    node_records_file: str = GENERATION_FILE
    defaults: BuildDefaults = SOLAR_BUILD_DEFAULTS
    false_data: FalseDataKnobs = SOLAR_FALSE_DATA
    weather_sources: tuple[str, ...] = tuple(source.value for source in WeatherSource)
    downloaded_weather_sources: tuple[str, ...] = (WeatherSource.open_meteo.value,)
    paper_weather_sha256: str | None = PAPER_WEATHER_SHA256
    split_rule: str = SPLIT_RULE
    families: tuple[str, ...] = (TMY_FAMILY, PAPER_CITIES_FAMILY)
    #: The paper's five cities (the default of a build that names none).
    default_cities: tuple[City, ...] = PAPER_CITIES
    #: What :meth:`build_point` reads: the scenario's parameters, the cities and their weather.
    parameters: tuple[str, ...] = (*SCENARIO_PARAMETERS, "timezone", "nodes_per_city", "cities", "weather_cache")

    def cities(self, specs: Sequence[str] | int | None) -> tuple[City, ...]:
        if specs is None:
            return self.default_cities
        cities = synthetic_cities(specs) if isinstance(specs, int) else tuple(parse_city(spec) for spec in specs)
        check_unique_prefixes(cities)
        return cities

    def scenario(self, rate: float, severity: str | None, pattern: str, burst_hours: int) -> FdiaScenario:
        return scenario_from_knobs(rate, severity, pattern, burst_hours)

    def choose_weather(self, cities: Sequence[City], start: str, end: str, **options: Any) -> Any:
        return choose_weather(cities, start, end, **options)

    def read_weather_files(self, specs: Sequence[str]) -> tuple[list, str]:
        read = []
        for spec in specs:
            name, path = parse_weather_file_spec(spec)
            read.append((name, read_weather_file(path)))
        return read, etc_zone(read[0][1].site.utc_offset_h)

    def weather_from_files(self, read: Any, timezone: str, start: str, end: str) -> tuple[tuple[City, ...], Any]:
        cities, weather = weather_from_files(read, timezone, start, end)
        check_unique_prefixes(cities)
        return cities, weather

    def build(
        self,
        weather: Any,
        out: Path,
        *,
        cities: Sequence[City],
        seed: int,
        start: str,
        end: str,
        nodes_per_city: int,
        timezone: str,
        scenario: FdiaScenario | None = None,
        progress: BuildProgress | None = None,
    ) -> dict[str, Any]:
        """Build with :func:`~solarchain_eval.data.build.build_dataset` from a weather of
        :meth:`choose_weather` or :meth:`weather_from_files` (whose file entries and licence the
        manifest records)."""
        from ..data.build import build_dataset

        files = {}
        if isinstance(weather, FileWeather):  # the manifest records the files and their licence
            files = {"weather_files": weather.entries, "attribution": weather.attribution}
        extra = {"progress": progress} if progress is not None else {}
        result = build_dataset(
            weather.payload,
            out,
            cities=cities,
            seed=seed,
            start=start,
            end=end,
            nodes_per_city=nodes_per_city,
            timezone=timezone,
            weather_source=weather.source,
            weather_sha256=weather.sha256,
            fdia=scenario,
            **files,
            **extra,
        )
        return result.manifest

    def build_point(self, out: Path, parameters: Mapping[str, Any]) -> dict[str, Any]:
        """A sweep point's build: the paper's cities use the cached weather file when
        ``weather_cache`` is given; any other cities (synthetic or listed) get synthetic weather."""
        p = parameters
        cities = self.cities(p["cities"])
        cached = p["weather_cache"] is not None and p["cities"] is None
        weather = self.choose_weather(
            cities,
            p["start"],
            p["end"],
            seed=p["seed"],
            timezone=p["timezone"],
            weather_cache=Path(p["weather_cache"]) if cached else None,
            source="synthetic",
        )
        scenario = self.scenario(p["fdia_rate"], p["fdia_severity"], p["fdia_pattern"], p["fdia_burst_hours"])
        return self.build(
            weather,
            out,
            cities=cities,
            seed=p["seed"],
            start=p["start"],
            end=p["end"],
            nodes_per_city=p["nodes_per_city"],
            timezone=p["timezone"],
            scenario=scenario,
        )

    def is_published(self, file_sha256: Mapping[str, str]) -> bool:
        return matches_published(file_sha256)

    def check(self, data_dir: Path) -> tuple[tuple[str, str], ...]:
        from ..data.load import load_raw_dataset
        from ..data.table import table_from_raw

        raw = load_raw_dataset(data_dir)
        table = table_from_raw(raw)
        gen = raw.generation
        return (
            ("hours", f"{raw.hours:,} from {raw.first_timestamp.isoformat()}"),
            ("cities", ", ".join(table.cities)),
            ("nodes", f"{gen['node_id'].nunique():,}"),
            ("generation records", f"{len(gen):,}"),
            ("FDIA-labelled records", f"{int(gen['fdia_detected'].sum()):,}"),
            ("rejected records", f"{int((~gen['verified']).sum()):,}"),
            ("trades", f"{len(raw.trades):,}"),
            ("mean raw violation rate ν", f"{table.raw_violation_rate.mean():.4f}"),
        )

    def splits(self) -> tuple[SplitSummary, ...]:
        out = []
        for split in SPLITS.values():
            (days,) = {entry.start_days for entry in split.entries}  # a split's datasets share their start days
            out.append(SplitSummary(split.name, split.role, split.description, split.datasets, days))
        return tuple(out)

    def family(self, family: str, months: Sequence[str | int] | None) -> tuple[FamilyMember, ...]:
        """``tmy-3sites``: months 1-12 (default all twelve); ``paper-cities``: months ``YYYY-MM``
        (default 2026-05 to 2026-10)."""
        if family == PAPER_CITIES_FAMILY:
            chosen = paper_cities_datasets(tuple(str(m) for m in months) if months else PAPER_CITIES_MONTHS)
            weather = "Weather data by Open-Meteo.com (CC BY 4.0), fetched online once and cached"
            return tuple(FamilyMember(d.name, d.start, d.end, d, pinned=False, weather=weather) for d in chosen)
        if family != TMY_FAMILY:
            raise WeatherError(f"unknown held-out family '{family}' (known: {', '.join(self.families)})")
        numbers = sorted({_month_number(family, m) for m in months}) if months else MONTHS
        members = (heldout_dataset(family, m) for m in numbers)
        return tuple(FamilyMember(d.name, d.start, d.end, d, weather="public NREL data (NSRDB)") for d in members)

    def build_family_member(self, member: FamilyMember, out: Path, *, replace: bool, **options: Any) -> dict[str, Any]:
        if member.handle.family == PAPER_CITIES_FAMILY:
            online = {key: options[key] for key in ("open_meteo_url", "retries", "notify") if key in options}
            target = build_online(member.handle, out, replace=replace, **online)
        else:
            target = build_checked(member.handle, out, replace=replace)
        return json.loads((target / MANIFEST_FILE).read_text(encoding="utf-8"))


def _month_number(family: str, month: str | int) -> int:
    """A month of ``tmy-3sites`` as given on the command line (``4``, ``04``) as its number."""
    if isinstance(month, int) or str(month).strip().isdigit():
        return int(month)
    raise WeatherError(f"{family}: month must be 1..12, got {month!r}")


#: The solar market's dataset builder (``SOLAR_TASK.dataset``).
SOLAR_DATASET = SolarDataset()
