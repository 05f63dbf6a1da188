"""The held-out family ``paper-cities``: the paper's market in other months, built online
(docs/dataset.md#held-out-family-paper-cities).

One dataset per calendar month, ``paper-cities-YYYY-MM``: the paper's five cities, its time zone
(Asia/Shanghai), its ten nodes per city, its seed and its attack scenario, so the weather and the
month are all that differ from the paper's dataset (built for 2026-04 from the paper's payload,
the design gives the paper's four CSVs byte for byte). The weather is Open-Meteo's archive (CC BY
4.0), fetched once per month and cached in the user cache directory, the cache ``data build
--weather open-meteo`` uses; a rebuild from the cached payload is byte-identical. April 2026 is
the paper's (train) month and is refused. No sha256 is pinned: Open-Meteo may revise its archive,
and each run's protocol id holds the dataset's own sha256s, so two revisions never share one.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from pathlib import Path

from ..common.atomic_files import sha256_file
from .cities import DEFAULT_NODES_PER_CITY, DEFAULT_SEED, DEFAULT_START, DEFAULT_TIMEZONE, PAPER_CITIES
from .default import cache_dir
from .files import MANIFEST_FILE
from .heldout import HeldoutDataset, build_checked, build_design
from .sources import Weather, open_meteo_cache_path
from .weather import CityWeather, WeatherError, read_weather_cache, write_weather_cache

PAPER_CITIES_FAMILY = "paper-cities"
#: The paper's own month: the train split's, so no dataset of this held-out family.
TRAIN_MONTH = DEFAULT_START[:7]
#: The family's default months: the six complete months after the paper's.
PAPER_CITIES_MONTHS = ("2026-05", "2026-06", "2026-07", "2026-08", "2026-09", "2026-10")
#: The archive's first year (Open-Meteo's historical reanalysis starts in 1940).
FIRST_YEAR = 1940
_MONTH_TEXT = re.compile(r"^(\d{4})-(\d{2})$")


def parse_month(text: str) -> tuple[int, int]:
    """``YYYY-MM`` as (year, month).

    Raises
    ------
    WeatherError
        Text that is not a month of the archive (one line naming the text).
    """
    found = _MONTH_TEXT.match(str(text).strip())
    if found is None or not 1 <= int(found.group(2)) <= 12:
        raise WeatherError(f"{PAPER_CITIES_FAMILY}: a month is YYYY-MM (e.g. 2026-05), got {text!r}")
    year, month = int(found.group(1)), int(found.group(2))
    if year < FIRST_YEAR:
        raise WeatherError(f"{PAPER_CITIES_FAMILY}: the Open-Meteo archive starts in {FIRST_YEAR}, got {text!r}")
    return year, month


def paper_cities_design(month: str) -> HeldoutDataset:
    """The design of the family's dataset for ``month`` (``YYYY-MM``), the paper's month included:
    the calendar month in Asia/Shanghai, the paper's seed and ten nodes per city."""
    year, number = parse_month(month)
    end_year, end_month = (year + 1, 1) if number == 12 else (year, number + 1)
    return HeldoutDataset(
        family=PAPER_CITIES_FAMILY,
        month=number,
        name=f"{PAPER_CITIES_FAMILY}-{year:04d}-{number:02d}",
        start=f"{year:04d}-{number:02d}-01",
        end=f"{end_year:04d}-{end_month:02d}-01",
        seed=DEFAULT_SEED,
        nodes_per_city=DEFAULT_NODES_PER_CITY,
        timezone=DEFAULT_TIMEZONE,
    )


def paper_cities_dataset(month: str) -> HeldoutDataset:
    """The family's dataset of ``month`` (``YYYY-MM``); the paper's month is refused.

    Raises
    ------
    WeatherError
        A bad month text, or April 2026 (the train split's month).
    """
    dataset = paper_cities_design(month)
    if dataset.start[:7] == TRAIN_MONTH:
        raise WeatherError(
            f"{PAPER_CITIES_FAMILY}: {TRAIN_MONTH} is the paper's month (the train split), "
            "not a held-out one; pick another month"
        )
    return dataset


def family_datasets(months: tuple[str, ...] = PAPER_CITIES_MONTHS) -> tuple[HeldoutDataset, ...]:
    """The family's datasets of ``months`` (default: 2026-05 to 2026-10), in calendar order, each once."""
    chosen = {paper_cities_dataset(month).name: paper_cities_dataset(month) for month in months}
    return tuple(chosen[name] for name in sorted(chosen))


def paper_cities_weather(
    dataset: HeldoutDataset,
    *,
    open_meteo_url: str | None = None,
    retries: int = 4,
    notify: Callable[[str], None] | None = None,
) -> Weather:
    """The month's Open-Meteo weather: the cached payload if there is one, else fetched and cached.

    The build always reads the cached file, so a first build and any rebuild read the same bytes.

    Raises
    ------
    WeatherError
        The archive cannot be reached (one line naming the URL) or answers something unusable.
    """
    from .open_meteo import SOURCE_NAME, archive_url, fetch_weather

    say = notify or (lambda _message: None)
    cached = open_meteo_cache_path(PAPER_CITIES, dataset.start, dataset.end)
    if cached.is_file():
        say(f"{dataset.name}: using cached Open-Meteo weather {cached}")
    else:
        url = open_meteo_url or archive_url()
        hint = f"The held-out family {PAPER_CITIES_FAMILY} is built online (once; later builds reuse the cache)."
        payload: Mapping[str, CityWeather] = fetch_weather(
            PAPER_CITIES, dataset.start, dataset.end, dataset.timezone, url=url, retries=retries, hint=hint
        )
        write_weather_cache(cached, payload)
        say(f"{dataset.name}: cached the Open-Meteo payload in {cached}")
    source = f"held-out family {PAPER_CITIES_FAMILY} (online, cached): {SOURCE_NAME}"
    return Weather(read_weather_cache(cached, PAPER_CITIES), source, sha256_file(cached))


def build_paper_cities(dataset: HeldoutDataset, weather: Weather, out_dir: str | Path, progress=None):
    """Build ``dataset`` from ``weather`` into ``out_dir`` (four CSVs and manifest.json); returns the build's result."""
    return build_design(
        dataset,
        out_dir,
        PAPER_CITIES,
        weather.payload,
        weather_source=weather.source,
        weather_sha256=weather.sha256,
        progress=progress,
    )


def build_online(
    dataset: HeldoutDataset,
    target: str | Path,
    *,
    replace: bool = False,
    open_meteo_url: str | None = None,
    retries: int = 4,
    notify: Callable[[str], None] | None = None,
) -> Path:
    """Build ``dataset`` into ``target``: its weather first (nothing is written when it cannot be
    had), then the build in a temporary directory renamed into place (see
    :func:`~solarchain_eval.data.heldout.build_checked`)."""
    weather = paper_cities_weather(dataset, open_meteo_url=open_meteo_url, retries=retries, notify=notify)

    def build(member: HeldoutDataset, out: Path, progress=None):
        return build_paper_cities(member, weather, out, progress=progress)

    return build_checked(dataset, target, replace=replace, build=build)


def paper_cities_dataset_dir(month: str, build: bool = True) -> Path:
    """The cached directory of the family's dataset of ``month``, built on first use (online once,
    from the cached payload afterwards)."""
    dataset = paper_cities_dataset(month)
    target = cache_dir() / "datasets" / dataset.name
    if (target / MANIFEST_FILE).is_file() or not build:
        return target
    return build_online(dataset, target)
