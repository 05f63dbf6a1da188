"""Hourly weather payloads in the layout of the paper's cached Open-Meteo file.

All three weather sources (cached file, live Open-Meteo archive, synthetic) produce the same
structure, one :class:`CityWeather` per city, so the dataset build does not know which one
it was given. On disk the layout is the paper's JSON: per city ``source``, ``latitude``,
``longitude``, ``timezone``, ``time`` (local wall-clock ISO strings), ``temperature_2m_C``
and ``shortwave_radiation_Wm2``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..common.atomic_files import atomic_write_text
from ..common.errors import InputDataError
from .cities import City


class WeatherError(InputDataError, ValueError):
    """A weather payload is missing, malformed or does not cover what the build needs."""


@dataclass(frozen=True)
class CityWeather:
    """Hourly weather of one city.

    Attributes
    ----------
    source : str
        Where the data came from (free text, kept in the manifest).
    latitude, longitude : float
        Coordinates of the weather grid cell, decimal degrees.
    timezone : str
        IANA time zone of the wall-clock ``time`` strings.
    time : tuple of str
        Local wall-clock times, ``YYYY-MM-DDTHH:MM``.
    temperature_2m_C : tuple of float
        Air temperature 2 m above ground, °C.
    shortwave_radiation_Wm2 : tuple of float
        Global horizontal shortwave irradiance, W/m².
    """

    source: str
    latitude: float
    longitude: float
    timezone: str
    time: tuple[str, ...]
    temperature_2m_C: tuple[float, ...]
    shortwave_radiation_Wm2: tuple[float, ...]

    def to_json(self) -> dict:
        return {
            "source": self.source,
            "latitude": self.latitude,
            "longitude": self.longitude,
            "timezone": self.timezone,
            "time": list(self.time),
            "temperature_2m_C": list(self.temperature_2m_C),
            "shortwave_radiation_Wm2": list(self.shortwave_radiation_Wm2),
        }


#: The CC BY 4.0 attribution of Open-Meteo weather, as a build manifest records it.
OPEN_METEO_ATTRIBUTION = {
    "attribution": "Weather data by Open-Meteo.com",
    "source_url": "https://open-meteo.com/",
    "licence": "CC BY 4.0",
    "licence_url": "https://creativecommons.org/licenses/by/4.0/",
    "changes": (
        "Hourly temperature_2m and shortwave_radiation of the Historical Weather API, re-laid out per city as "
        "temperature_2m_C and shortwave_radiation_Wm2 with values unchanged (the paper's payload ships "
        "xz-compressed). The build caps the irradiance at 1.08 x clear-sky GHI (0 with the sun below the "
        "horizon) and derives PV power, false-data injection, market aggregates and trades from it."
    ),
}


def weather_attribution(entries: Iterable[CityWeather]) -> dict[str, str] | None:
    """The attribution a dataset built from ``entries`` must carry (None without third-party data).

    Open-Meteo weather (CC BY 4.0) is recognised by its ``source`` field, which the archive
    client and the paper's payload set to the API's name.
    """
    if any("open-meteo" in entry.source.lower() for entry in entries):
        return dict(OPEN_METEO_ATTRIBUTION)
    return None


_FIELDS = ("source", "latitude", "longitude", "timezone", "time", "temperature_2m_C", "shortwave_radiation_Wm2")


def _numbers(values: object, where: str, field: str) -> tuple[float, ...]:
    if not isinstance(values, list):
        raise WeatherError(f"{where}: '{field}' must be a list of numbers")
    out = []
    for index, value in enumerate(values):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise WeatherError(f"{where}: '{field}'[{index}] is {value!r}, not a finite number")
        out.append(float(value))
    return tuple(out)


def city_weather_from_json(payload: Mapping, where: str) -> CityWeather:
    """Validate one city's entry of the cached layout."""
    if not isinstance(payload, Mapping):
        raise WeatherError(f"{where}: expected an object with keys {', '.join(_FIELDS)}")
    missing = [key for key in _FIELDS if key not in payload]
    if missing:
        raise WeatherError(f"{where}: missing key(s) {', '.join(missing)}")
    times = payload["time"]
    if not isinstance(times, list) or not all(isinstance(t, str) for t in times):
        raise WeatherError(f"{where}: 'time' must be a list of ISO time strings")
    temperature = _numbers(payload["temperature_2m_C"], where, "temperature_2m_C")
    radiation = _numbers(payload["shortwave_radiation_Wm2"], where, "shortwave_radiation_Wm2")
    if not (len(times) == len(temperature) == len(radiation)):
        raise WeatherError(
            f"{where}: 'time' ({len(times)}), 'temperature_2m_C' ({len(temperature)}) and "
            f"'shortwave_radiation_Wm2' ({len(radiation)}) differ in length"
        )
    try:
        latitude, longitude = float(payload["latitude"]), float(payload["longitude"])
    except (TypeError, ValueError):
        raise WeatherError(f"{where}: latitude/longitude must be numbers") from None
    return CityWeather(
        source=str(payload["source"]),
        latitude=latitude,
        longitude=longitude,
        timezone=str(payload["timezone"]),
        time=tuple(times),
        temperature_2m_C=temperature,
        shortwave_radiation_Wm2=radiation,
    )


def read_weather_cache(path: str | Path, cities: Sequence[City]) -> dict[str, CityWeather]:
    """Read a cached weather file and return the entries of ``cities`` (validated)."""
    cache = Path(path)
    if not cache.is_file():
        raise WeatherError(f"weather cache not found: {cache}")
    return parse_weather_json(cache.read_text(encoding="utf-8"), str(cache), cities)


def parse_weather_json(text: str, where: str, cities: Sequence[City]) -> dict[str, CityWeather]:
    """Parse a payload in the cached layout and return the entries of ``cities`` (validated).

    ``where`` names the payload in error messages.
    """
    try:
        payload = json.loads(text)
    except json.JSONDecodeError as error:
        raise WeatherError(f"{where} is not valid JSON: {error}") from None
    if not isinstance(payload, dict):
        raise WeatherError(f"{where}: the top level must map city names to weather objects")
    absent = [city.name for city in cities if city.name not in payload]
    if absent:
        raise WeatherError(
            f"{where}: no weather for {', '.join(absent)} (the file has {', '.join(payload) or 'no cities'})"
        )
    return {city.name: city_weather_from_json(payload[city.name], f"{where} [{city.name}]") for city in cities}


def write_weather_cache(path: str | Path, weather: Mapping[str, CityWeather]) -> Path:
    """Write ``weather`` in the cached layout, atomically."""
    text = json.dumps({name: item.to_json() for name, item in weather.items()}, indent=2)
    return atomic_write_text(Path(path), text + "\n")
