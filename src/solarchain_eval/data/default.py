"""The embedded default dataset: the paper's published dataset, rebuilt from the packaged weather.

Built offline on first use into the user's cache directory and reused afterwards. The build
goes to a temporary directory that is renamed into place only once its four CSVs match the
published sha256s, so concurrent first uses (worker processes) never see a half-built dataset
and a build that does not reproduce the paper's files leaves nothing behind.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from pathlib import Path

from ..common.atomic_files import sha256_file
from ..common.cache import cache_dir as cache_dir  # its home is common/cache.py; named here as before
from .cities import DEFAULT_END, DEFAULT_NODES_PER_CITY, DEFAULT_SEED, DEFAULT_START, DEFAULT_TIMEZONE, PAPER_CITIES
from .files import DATASET_FILES, MANIFEST_FILE
from .published import (
    PAPER_WEATHER_SHA256,
    PAPER_WEATHER_SOURCE,
    PublishedMismatchError,
    published_mismatches,
    read_paper_weather,
)

#: The cache key names the payload, so no other dataset (an older synthetic default) is taken for it.
DEFAULT_DATASET_NAME = f"paper-published-2026-04-{PAPER_WEATHER_SHA256[:12]}"

logger = logging.getLogger(__name__)


def resolve_data_dir(data_dir: str | Path | None, config_data_dir: str | Path | None = None) -> Path:
    """The dataset directory to use: ``data_dir``, else the config's ``data_dir``, else the default dataset.

    The one rule every entry point follows (env, ``evaluate``, training, ``paper``); the embedded
    default dataset is built on first use.
    """
    if data_dir:
        return Path(data_dir)
    if config_data_dir:
        return Path(config_data_dir)
    return default_dataset_dir()


def default_dataset_dir(build: bool = True) -> Path:
    """Directory of the default dataset, building it if it is not there yet.

    Raises
    ------
    PackagedWeatherError
        The packaged weather payload is missing or damaged.
    PublishedMismatchError
        The rebuild differs from the published CSVs (nothing is left in the cache).
    """
    target = cache_dir() / "datasets" / DEFAULT_DATASET_NAME
    if (target / MANIFEST_FILE).is_file() or not build:
        return target
    weather = read_paper_weather(PAPER_CITIES)  # checks the payload's sha256 before anything is written
    # A one-time build of seconds: say so (WARNING so Python's last-resort handler shows it on stderr).
    logger.warning("solarchain-eval: building the paper's published dataset once into %s (a few seconds)...", target)
    target.parent.mkdir(parents=True, exist_ok=True)
    from .build import build_dataset  # pvlib is only needed when building

    staging = Path(tempfile.mkdtemp(prefix=f".{DEFAULT_DATASET_NAME}.", dir=target.parent))
    try:
        build_dataset(
            weather,
            staging,
            cities=PAPER_CITIES,
            seed=DEFAULT_SEED,
            start=DEFAULT_START,
            end=DEFAULT_END,
            nodes_per_city=DEFAULT_NODES_PER_CITY,
            timezone=DEFAULT_TIMEZONE,
            weather_source=PAPER_WEATHER_SOURCE,
            weather_sha256=PAPER_WEATHER_SHA256,
        )
        # The files on disk, not the manifest's record of them, are what users will read.
        mismatched = published_mismatches({name: sha256_file(staging / name) for name in DATASET_FILES})
        if mismatched:
            raise PublishedMismatchError(target, mismatched)
        if target.exists() and not (target / MANIFEST_FILE).is_file():
            shutil.rmtree(target)  # a stale partial directory from an older version
        try:
            os.rename(staging, target)
        except OSError:
            if not (target / MANIFEST_FILE).is_file():  # lost a race to a broken writer
                raise
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    return target
