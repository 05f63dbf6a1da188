"""Client for the Open-Meteo historical-weather (archive) API.

Requests hourly ``temperature_2m`` and ``shortwave_radiation`` per city in the dataset's time
zone, retries transient failures with exponential back-off, and converts each response to the
cached layout (:class:`~solarchain_eval.data.weather.CityWeather`).
"""

from __future__ import annotations

import datetime as dt
import math
import os
import time
from collections.abc import Callable, Sequence

import httpx

from .cities import City
from .weather import CityWeather, WeatherError

DEFAULT_ARCHIVE_URL = "https://archive-api.open-meteo.com/v1/archive"
SOURCE_NAME = "Open-Meteo Historical Weather API"
#: What the error of an unreachable archive suggests to a ``data build`` user.
OFFLINE_HINT = "Offline? Use --weather-cache FILE (a cached payload) or --weather synthetic."
_RETRY_STATUS = {429, 500, 502, 503, 504}


def archive_url() -> str:
    """The archive endpoint; ``SOLARCHAIN_OPEN_METEO_URL`` overrides the public one."""
    return os.environ.get("SOLARCHAIN_OPEN_METEO_URL", DEFAULT_ARCHIVE_URL)


def _hourly_values(payload: dict, name: str, city: str, n: int) -> tuple[float, ...]:
    values = payload["hourly"].get(name)
    if not isinstance(values, list) or len(values) != n:
        raise WeatherError(f"Open-Meteo response for {city}: 'hourly.{name}' is missing or has the wrong length")
    out = []
    for index, value in enumerate(values):
        if value is None or isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise WeatherError(
                f"Open-Meteo response for {city}: 'hourly.{name}'[{index}] "
                f"({payload['hourly']['time'][index]}) is {value!r}, not a number"
            )
        out.append(float(value))
    return tuple(out)


def parse_archive_response(payload: object, city: City, timezone: str) -> CityWeather:
    """Convert one archive API JSON response to the cached layout."""
    if not isinstance(payload, dict) or not isinstance(payload.get("hourly"), dict):
        raise WeatherError(f"Open-Meteo response for {city.name} has no 'hourly' object")
    times = payload["hourly"].get("time")
    if not isinstance(times, list) or not times or not all(isinstance(t, str) for t in times):
        raise WeatherError(f"Open-Meteo response for {city.name}: 'hourly.time' is missing or empty")
    n = len(times)
    return CityWeather(
        source=SOURCE_NAME,
        latitude=float(payload.get("latitude", city.latitude)),
        longitude=float(payload.get("longitude", city.longitude)),
        timezone=str(payload.get("timezone", timezone)),
        time=tuple(times),
        temperature_2m_C=_hourly_values(payload, "temperature_2m", city.name, n),
        shortwave_radiation_Wm2=_hourly_values(payload, "shortwave_radiation", city.name, n),
    )


def fetch_city(
    client: httpx.Client,
    url: str,
    city: City,
    start: str,
    end: str,
    timezone: str,
    *,
    retries: int = 4,
    backoff_s: float = 1.0,
    sleep: Callable[[float], None] = time.sleep,
    hint: str = OFFLINE_HINT,
) -> CityWeather:
    """Fetch [start, end) for one city. ``end`` is exclusive; the API's end_date is inclusive.

    ``hint`` ends the error of an archive still unreachable after the retries (what to do instead)."""
    last_day = (dt.date.fromisoformat(end) - dt.timedelta(days=1)).isoformat()
    params = {
        "latitude": city.latitude,
        "longitude": city.longitude,
        "start_date": start,
        "end_date": last_day,
        "hourly": "temperature_2m,shortwave_radiation",
        "timezone": timezone,
    }
    problem = "no attempt made"
    for attempt in range(retries + 1):
        if attempt:
            sleep(backoff_s * 2 ** (attempt - 1))
        try:
            response = client.get(url, params=params)
        except httpx.TransportError as error:
            problem = f"{type(error).__name__}: {error}"
            continue
        if response.status_code in _RETRY_STATUS:
            problem = f"HTTP {response.status_code}"
            continue
        if response.status_code != 200:
            detail = response.text[:300]
            raise WeatherError(f"Open-Meteo refused the request for {city.name}: HTTP {response.status_code}: {detail}")
        try:
            payload = response.json()
        except ValueError:
            raise WeatherError(f"Open-Meteo answered for {city.name} with something that is not JSON") from None
        return parse_archive_response(payload, city, timezone)
    raise WeatherError(
        f"could not get weather for {city.name} from {url} after {retries + 1} attempts ({problem}). {hint}"
    )


def fetch_weather(
    cities: Sequence[City],
    start: str,
    end: str,
    timezone: str,
    *,
    url: str | None = None,
    timeout_s: float = 30.0,
    retries: int = 4,
    backoff_s: float = 1.0,
    on_city: Callable[[str], None] | None = None,
    hint: str = OFFLINE_HINT,
) -> dict[str, CityWeather]:
    """Fetch every city's hourly weather from the archive API (``hint``: as for :func:`fetch_city`)."""
    endpoint = url or archive_url()
    weather: dict[str, CityWeather] = {}
    with httpx.Client(timeout=timeout_s, headers={"User-Agent": "solarchain-eval"}) as client:
        for city in cities:
            weather[city.name] = fetch_city(
                client, endpoint, city, start, end, timezone, retries=retries, backoff_s=backoff_s, hint=hint
            )
            if on_city is not None:
                on_city(city.name)
    return weather
