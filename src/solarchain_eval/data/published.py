"""The paper's published data: its weather payload, shipped with the package, and the release's checksums.

The paper built its four CSVs from one Open-Meteo payload (CC BY 4.0, see docs/dataset.md). The
payload ships xz-compressed as package data in ``data/paper/``, beside the release's
``SHA256SUMS`` (the payload's and the four CSVs'). The CSVs themselves are not shipped: the
build remakes them byte for byte, and these checksums tell when it did.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import lzma
from collections.abc import Mapping, Sequence
from importlib.resources import files
from pathlib import Path

from .cities import DEFAULT_END, DEFAULT_START, DEFAULT_TIMEZONE, PAPER_CITIES, City
from .errors import DatasetError
from .files import DATASET_FILES
from .weather import CityWeather, WeatherError, parse_weather_json

PAPER_WEATHER_FILE = "open_meteo_weather_2026-04-01_2026-05-01.json"
PUBLISHED_DIR = "published_2026_04"
#: The packaged payload, xz-compressed; :func:`read_paper_weather_bytes` checks its sha256.
PAPER_WEATHER_RESOURCE = files(__package__).joinpath("paper", f"{PAPER_WEATHER_FILE}.xz")
#: The release's checksums of the payload (uncompressed JSON) and of the four CSVs, ``sha256sum`` format.
CHECKSUMS_RESOURCE = files(__package__).joinpath("paper", "SHA256SUMS")
#: The manifest's ``weather_source`` of a build from the packaged payload.
PAPER_WEATHER_SOURCE = f"Open-Meteo Historical Weather API: the paper's payload {PAPER_WEATHER_FILE} (packaged)"


class PackagedWeatherError(WeatherError):
    """The paper's packaged weather payload is missing or damaged."""


class PublishedMismatchError(DatasetError):
    """A rebuild of the paper's dataset differs from the published files.

    Attributes
    ----------
    mismatched : dict
        File name -> (sha256 of the rebuilt file, sha256 of the published one).
    """

    def __init__(self, target: Path | str, mismatched: Mapping[str, tuple[str, str]]):
        self.mismatched = dict(mismatched)
        listed = "; ".join(
            f"{name} has sha256 {got}, the published file {expected}" for name, (got, expected) in mismatched.items()
        )
        super().__init__(
            target,
            f"not built: the rebuild differs from the paper's published dataset ({listed}). Nothing was written; "
            "pass a dataset directory (--data / data_dir) to work without the default dataset",
        )


def _read_checksums() -> dict[str, str]:
    sums = {}
    for line in CHECKSUMS_RESOURCE.read_text(encoding="utf-8").splitlines():
        if line.strip():
            digest, name = line.split(maxsplit=1)
            sums[name.strip().lstrip("*")] = digest
    return sums


_SUMS = _read_checksums()

#: sha256 of the paper's Open-Meteo payload (the uncompressed JSON).
PAPER_WEATHER_SHA256 = _SUMS[PAPER_WEATHER_FILE]

#: sha256 of the four CSVs published with the paper (seed 20260511, April 2026).
PAPER_DATASET_SHA256 = {name: _SUMS[f"{PUBLISHED_DIR}/{name}"] for name in sorted(DATASET_FILES)}


def read_paper_weather_bytes() -> bytes:
    """The packaged payload's JSON, decompressed and checked against its sha256.

    Raises
    ------
    PackagedWeatherError
        The file is missing, is not valid xz, or its JSON has another sha256.
    """
    resource = PAPER_WEATHER_RESOURCE
    reinstall = "reinstall solarchain-eval"
    try:
        compressed = resource.read_bytes()
    except OSError as error:
        raise PackagedWeatherError(
            f"the paper's weather payload {resource} cannot be read ({error}); {reinstall}"
        ) from None
    try:
        raw = lzma.decompress(compressed, format=lzma.FORMAT_XZ)
    except (lzma.LZMAError, EOFError) as error:
        raise PackagedWeatherError(
            f"the paper's weather payload {resource} is damaged ({error}); {reinstall}"
        ) from None
    digest = hashlib.sha256(raw).hexdigest()
    if digest != PAPER_WEATHER_SHA256:
        raise PackagedWeatherError(
            f"the paper's weather payload {resource} is damaged: its JSON has sha256 {digest}, "
            f"not the paper's {PAPER_WEATHER_SHA256}; {reinstall}"
        )
    return raw


def paper_weather_covers(cities: Sequence[City], start: str, end: str, timezone: str) -> bool:
    """Whether the packaged payload has the weather of a build: the paper's cities (name and
    coordinates), its time zone and dates inside its month."""
    try:
        first, stop = dt.date.fromisoformat(start), dt.date.fromisoformat(end)
    except ValueError:
        return False
    inside = dt.date.fromisoformat(DEFAULT_START) <= first < stop <= dt.date.fromisoformat(DEFAULT_END)
    return inside and timezone == DEFAULT_TIMEZONE and all(city in PAPER_CITIES for city in cities)


def read_paper_weather(cities: Sequence[City] = PAPER_CITIES) -> dict[str, CityWeather]:
    """The packaged payload's weather of ``cities`` (checked; see :func:`read_paper_weather_bytes`)."""
    unknown = [city.name for city in cities if city not in PAPER_CITIES]
    if unknown:
        raise WeatherError(
            f"the paper's weather covers only its five cities ({', '.join(c.name for c in PAPER_CITIES)}), "
            f"not {', '.join(unknown)}"
        )
    text = read_paper_weather_bytes().decode("utf-8")
    return parse_weather_json(text, f"the paper's weather payload {PAPER_WEATHER_FILE}", cities)


def published_mismatches(file_hashes: Mapping[str, str]) -> dict[str, tuple[str, str]]:
    """File name -> (given sha256, published sha256) for each published CSV that ``file_hashes`` does not match."""
    return {
        name: (file_hashes.get(name, "(missing)"), digest)
        for name, digest in PAPER_DATASET_SHA256.items()
        if file_hashes.get(name) != digest
    }


def matches_published(file_hashes: Mapping[str, str]) -> bool:
    """Whether ``file_hashes`` (file name -> sha256) are the four published CSVs'."""
    return not published_mismatches(file_hashes)
