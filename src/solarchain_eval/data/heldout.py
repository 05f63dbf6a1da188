"""Held-out dataset families, built offline from weather shipped with the package (docs/dataset.md#held-out-family-tmy-3sites).

``tmy-3sites``: twelve one-month datasets of a market whose cities are the three typical-year
sites pvlib ships (public NREL data): Greensboro NC (TMY3), Sand Point AK (TMY3) and Miami FL
(TMY2). The three files ship xz-compressed in ``data/tmy/`` beside ``SHA256SUMS``, which
holds the sha256 of each file (uncompressed) and of the four CSVs of every month, so a rebuild
is checked byte for byte. The design (market clock, year, nodes, seeds, attacks) is the
family's card in docs/dataset.md.
"""

from __future__ import annotations

import functools
import hashlib
import lzma
import os
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

from ..common.atomic_files import sha256_file
from .cities import DEFAULT_NODES_PER_CITY, DEFAULT_SEED, City
from .default import cache_dir
from .errors import DatasetError
from .files import DATASET_FILES, MANIFEST_FILE
from .published import PackagedWeatherError
from .weather import WeatherError
from .weather_files import FileWeather, WeatherFile, read_weather_file, weather_from_files

TMY_FAMILY = "tmy-3sites"
#: The family's cities, in build order: (city name, file shipped in data/tmy/).
TMY_SITES = (("Greensboro", "723170TYA.CSV"), ("Sand Point", "703165TY.csv"), ("Miami", "12839.tm2"))
#: The market clock: UTC-9 (Sand Point's standard time), so every daylight hour of all three
#: cities falls inside one calendar day of the clock, all year, and daily episodes never cut a day.
TMY_TIMEZONE = "Etc/GMT+9"
#: The calendar year the typical year is laid on: non-leap and later than any observation.
TMY_YEAR = 2027
MONTHS = tuple(range(1, 13))

_RESOURCES = files(__package__).joinpath("tmy")


@dataclass(frozen=True)
class HeldoutDataset:
    """One dataset of a held-out family: its name and the build's arguments."""

    family: str
    month: int
    name: str
    start: str
    end: str
    seed: int
    nodes_per_city: int
    timezone: str


def _read_sums() -> dict[str, str]:
    sums = {}
    for line in _RESOURCES.joinpath("SHA256SUMS").read_text(encoding="utf-8").splitlines():
        if line.strip():
            digest, name = line.split(maxsplit=1)
            sums[name.strip()] = digest
    return sums


_SUMS = _read_sums()


def heldout_dataset(family: str, month: int) -> HeldoutDataset:
    """The dataset of ``month`` (1-12) of ``family``: the month of :data:`TMY_YEAR`, seed
    ``DEFAULT_SEED + month``, the paper's ten nodes per city."""
    if family != TMY_FAMILY:
        raise WeatherError(f"unknown held-out family '{family}' (known: {TMY_FAMILY})")
    if month not in MONTHS:
        raise WeatherError(f"{family}: month must be 1..12, got {month}")
    end_year, end_month = (TMY_YEAR + 1, 1) if month == 12 else (TMY_YEAR, month + 1)
    return HeldoutDataset(
        family=family,
        month=month,
        name=f"{family}-{month:02d}",
        start=f"{TMY_YEAR}-{month:02d}-01",
        end=f"{end_year}-{end_month:02d}-01",
        seed=DEFAULT_SEED + month,
        nodes_per_city=DEFAULT_NODES_PER_CITY,
        timezone=TMY_TIMEZONE,
    )


def family_datasets(family: str = TMY_FAMILY) -> tuple[HeldoutDataset, ...]:
    """Every dataset of ``family``, month by month."""
    return tuple(heldout_dataset(family, month) for month in MONTHS)


def pinned_sha256(name: str) -> dict[str, str]:
    """The shipped sha256 of each CSV of dataset ``name`` (e.g. ``tmy-3sites-04``)."""
    return {file: _SUMS[f"{name}/{file}"] for file in DATASET_FILES if f"{name}/{file}" in _SUMS}


@functools.lru_cache(maxsize=1)
def read_tmy_files() -> tuple[tuple[str, WeatherFile], ...]:
    """The family's three weather files, decompressed, checked against their sha256 and read
    (pvlib's TMY2 reader takes seconds, so a process reads them once)."""
    with tempfile.TemporaryDirectory(prefix="solarchain-tmy-") as folder:
        out = []
        for city, name in TMY_SITES:
            resource = _RESOURCES.joinpath(f"{name}.xz")
            try:
                raw = lzma.decompress(resource.read_bytes(), format=lzma.FORMAT_XZ)
            except (OSError, lzma.LZMAError, EOFError) as error:
                raise PackagedWeatherError(
                    f"the packaged weather file {resource} cannot be read ({error}); reinstall"
                ) from None
            digest = hashlib.sha256(raw).hexdigest()
            if digest != _SUMS[name]:
                raise PackagedWeatherError(
                    f"the packaged weather file {resource} is damaged: sha256 {digest}, not {_SUMS[name]}; reinstall"
                )
            path = Path(folder) / name
            path.write_bytes(raw)
            out.append((city, read_weather_file(path)))
        return tuple(out)


def tmy_weather(dataset: HeldoutDataset) -> tuple[tuple[City, ...], FileWeather]:
    """The cities and weather of one dataset of the family."""
    return weather_from_files(read_tmy_files(), dataset.timezone, dataset.start, dataset.end)


def build_design(
    dataset: HeldoutDataset,
    out_dir: str | Path,
    cities,
    weather_payload,
    *,
    weather_source: str,
    weather_sha256: str,
    progress=None,
    **manifest,
):
    """Build a held-out family's ``dataset`` from its cities and weather into ``out_dir`` (four CSVs
    and manifest.json, which records the family and ``manifest``'s entries); returns the build's result."""
    from .build import build_dataset

    extra = {"progress": progress} if progress is not None else {}
    return build_dataset(
        weather_payload,
        out_dir,
        cities=cities,
        seed=dataset.seed,
        start=dataset.start,
        end=dataset.end,
        nodes_per_city=dataset.nodes_per_city,
        timezone=dataset.timezone,
        weather_source=weather_source,
        weather_sha256=weather_sha256,
        family=dataset.family,
        **manifest,
        **extra,
    )


def build_heldout(dataset: HeldoutDataset, out_dir: str | Path, progress=None):
    """Build ``dataset`` from the packaged weather files into ``out_dir``; returns the build's result."""
    cities, weather = tmy_weather(dataset)
    return build_design(
        dataset,
        out_dir,
        cities,
        weather.payload,
        weather_source=f"held-out family {dataset.family} (packaged): {weather.source}",
        weather_sha256=weather.sha256,
        weather_files=weather.entries,
        attribution=weather.attribution,
        progress=progress,
    )


def mismatches(name: str, file_hashes: Mapping[str, str]) -> dict[str, tuple[str, str]]:
    """File -> (given sha256, shipped sha256) for each CSV of ``name`` that ``file_hashes`` does not match."""
    return {
        file: (file_hashes.get(file, "(missing)"), digest)
        for file, digest in pinned_sha256(name).items()
        if file_hashes.get(file) != digest
    }


def heldout_dataset_dir(family: str, month: int, build: bool = True) -> Path:
    """The cached directory of a held-out dataset, built on first use (see :func:`build_checked`)."""
    dataset = heldout_dataset(family, month)
    target = cache_dir() / "datasets" / dataset.name
    if (target / MANIFEST_FILE).is_file() or not build:
        return target
    return build_checked(dataset, target)


def build_checked(
    dataset: HeldoutDataset, target: str | Path, progress=None, replace: bool = False, build=build_heldout
) -> Path:
    """Build ``dataset`` into ``target`` only if its CSVs match the shipped sha256s (when it has any).

    ``build(dataset, out_dir, progress=...)`` writes the dataset (default: :func:`build_heldout`,
    from the packaged weather). As for the default dataset, the build goes to a temporary directory renamed into place only
    when its CSVs match, so nothing half-built or different is ever left behind. ``replace``
    removes a complete dataset already in ``target`` first (otherwise it is kept).

    Raises
    ------
    DatasetError
        The rebuild differs from the shipped checksums (nothing is written).
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{dataset.name}.", dir=target.parent))
    try:
        build(dataset, staging, progress=progress)
        wrong = mismatches(dataset.name, {name: sha256_file(staging / name) for name in DATASET_FILES})
        if wrong:
            listed = "; ".join(
                f"{name} has sha256 {got}, the shipped one {want}" for name, (got, want) in wrong.items()
            )
            raise DatasetError(target, f"not built: the rebuild differs from the shipped checksums ({listed})")
        if target.exists() and (replace or not (target / MANIFEST_FILE).is_file()):
            shutil.rmtree(target)
        try:
            os.rename(staging, target)
        except OSError:
            if not (target / MANIFEST_FILE).is_file():
                raise
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    return target
