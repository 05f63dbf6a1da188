"""Where a dataset build's weather comes from: a cached file, the paper's packaged payload, Open-Meteo
(with its cache), or the synthetic generator.

:func:`choose_weather` is the one place that decides it, for ``data build`` and any other caller.
Without a choice, a build of the paper's cities, time zone and month gets the paper's payload
(shipped with the package) and any other build synthetic weather.
The Open-Meteo payload is cached in the user cache directory under a name derived from the
cities and the dates (:func:`open_meteo_cache_path`) and reused unless ``refresh`` is asked for.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from ..common.atomic_files import sha256_file
from .cities import City
from .default import cache_dir
from .published import PAPER_WEATHER_SHA256, PAPER_WEATHER_SOURCE, paper_weather_covers, read_paper_weather
from .weather import CityWeather, WeatherError, read_weather_cache, write_weather_cache


class WeatherSource(StrEnum):
    """Weather source of a build without a cached weather file."""

    paper = "paper"
    synthetic = "synthetic"
    open_meteo = "open-meteo"


@dataclass(frozen=True)
class Weather:
    """The weather of a build and how the manifest describes it.

    Attributes
    ----------
    payload : mapping
        City name -> its hourly weather.
    source : str
        The manifest's ``weather_source``.
    sha256 : str or None
        sha256 of the weather JSON read or cached (None for synthetic weather).
    """

    payload: Mapping[str, CityWeather]
    source: str
    sha256: str | None


def open_meteo_cache_path(cities: Sequence[City], start: str, end: str) -> Path:
    """The cache file of the Open-Meteo payload for these cities (name and coordinates) and dates."""
    key = hashlib.sha256(repr([(c.name, c.latitude, c.longitude) for c in cities]).encode()).hexdigest()[:10]
    return cache_dir() / "weather" / f"open_meteo_weather_{start}_{end}_{key}.json"


def choose_weather(
    cities: Sequence[City],
    start: str,
    end: str,
    *,
    seed: int,
    timezone: str,
    weather_cache: Path | None = None,
    source: WeatherSource | str | None = None,
    open_meteo_url: str | None = None,
    refresh: bool = False,
    retries: int = 4,
    on_city: Callable[[str], None] | None = None,
    notify: Callable[[str], None] | None = None,
) -> Weather:
    """The build's weather: ``weather_cache`` if given, else ``source``, else the default.

    The default is the paper's packaged payload when it covers the build (the paper's cities,
    time zone and dates in April 2026), synthetic weather otherwise.

    Parameters
    ----------
    cities, start, end, seed, timezone
        As for the build (``seed`` drives the synthetic generator).
    weather_cache : path, optional
        A weather file in the paper's layout; wins over ``source``.
    source : {"paper", "synthetic", "open-meteo"}, optional
        ``paper``: the paper's Open-Meteo payload shipped with the package (its sha256 checked).
        None: ``paper`` when it covers the build, else ``synthetic``.
    open_meteo_url : str, optional
        Archive endpoint (default: ``$SOLARCHAIN_OPEN_METEO_URL`` or the public API).
    refresh : bool
        Download Open-Meteo weather even if it is cached.
    retries : int
        Retries per Open-Meteo request.
    on_city : callable, optional
        Called with each city's name as its weather arrives from Open-Meteo.
    notify : callable, optional
        Called with one-line notices (cache used, cache written).

    Raises
    ------
    ValueError
        Dates the synthetic generator cannot cover.
    WeatherError
        A weather file or an Open-Meteo answer that cannot be used, a damaged packaged payload
        (:class:`~solarchain_eval.data.published.PackagedWeatherError`), or ``paper`` for a build
        it does not cover.
    """
    say = notify or (lambda _message: None)
    if weather_cache is not None:
        payload = read_weather_cache(weather_cache, cities)
        return Weather(payload, f"cached file {weather_cache.name}", sha256_file(weather_cache))
    covered = paper_weather_covers(cities, start, end, timezone)
    if source is None:
        source = WeatherSource.paper if covered else WeatherSource.synthetic
        if not covered:
            say("weather: synthetic (the paper's packaged weather covers its five cities, Asia/Shanghai, April 2026)")
    if WeatherSource(source) is WeatherSource.paper:
        if not covered:
            raise WeatherError(
                "the paper's weather covers only its five cities, the Asia/Shanghai time zone and dates from "
                "2026-04-01 to 2026-05-01; use synthetic or Open-Meteo weather for this build"
            )
        return Weather(read_paper_weather(cities), PAPER_WEATHER_SOURCE, PAPER_WEATHER_SHA256)
    if WeatherSource(source) is WeatherSource.open_meteo:
        from .open_meteo import SOURCE_NAME, archive_url, fetch_weather

        cached = open_meteo_cache_path(cities, start, end)
        if cached.is_file() and not refresh:
            say(f"using cached Open-Meteo weather {cached}")
            payload = read_weather_cache(cached, cities)
        else:
            url = open_meteo_url or archive_url()
            payload = fetch_weather(cities, start, end, timezone, url=url, retries=retries, on_city=on_city)
            write_weather_cache(cached, payload)
            say(f"cached the Open-Meteo payload in {cached}")
        return Weather(payload, SOURCE_NAME, sha256_file(cached))
    from .synthetic import SYNTHETIC_SOURCE, synthesize_weather

    return Weather(synthesize_weather(cities, start, end, seed, timezone), SYNTHETIC_SOURCE, None)
