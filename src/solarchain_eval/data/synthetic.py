"""Synthetic weather: pvlib clear-sky irradiance under a seeded stochastic cloud process.

The offline default source. For each city, a daily cloudiness regime (a persistent Markov
chain between clear, mixed and overcast days) sets the mean clearness index; an hourly AR(1)
process adds passing clouds. Shortwave radiation is the Ineichen clear-sky GHI times the
clearness index. Air temperature follows a seasonal/latitude mean, a day-to-day random walk
and a diurnal cycle whose amplitude shrinks under clouds. Values are rounded like the
Open-Meteo archive (radiation to 1 W/m², temperature to 0.1 °C). Each city has its own
random stream derived from (seed, city name), so adding a city never changes another's weather.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence

import numpy as np
import pandas as pd
from pvlib.location import Location

from .cities import City
from .weather import CityWeather

SYNTHETIC_SOURCE = "synthetic: pvlib Ineichen clear sky x seeded Markov/AR(1) cloud process"

# Daily regimes: clear, mixed, overcast. Mean clearness index and its day-to-day spread.
_REGIME_MEAN = np.array([0.78, 0.52, 0.22])
_REGIME_SPREAD = np.array([0.06, 0.10, 0.08])
_REGIME_TRANSITIONS = np.array(
    [
        [0.65, 0.25, 0.10],
        [0.30, 0.45, 0.25],
        [0.20, 0.35, 0.45],
    ]
)
_HOURLY_AR = 0.7
_HOURLY_SIGMA = 0.08


def hourly_times(start: str, end: str, timezone: str) -> pd.DatetimeIndex:
    """Local hourly timestamps in [start, end)."""
    first = pd.Timestamp(start).tz_localize(timezone)
    last = pd.Timestamp(end).tz_localize(timezone)
    if last <= first:
        raise ValueError(f"end date {end} must be after start date {start}")
    return pd.date_range(first, last, freq="h", inclusive="left")


def _city_rng(seed: int, city: City) -> np.random.Generator:
    return np.random.default_rng([int(seed), 0x5EA7, zlib.crc32(city.name.encode("utf-8"))])


def synthesize_city_weather(city: City, start: str, end: str, seed: int, timezone: str) -> CityWeather:
    times = hourly_times(start, end, timezone)
    rng = _city_rng(seed, city)
    location = Location(city.latitude, city.longitude, tz=timezone)
    ghi = np.maximum(location.get_clearsky(times, model="ineichen")["ghi"].to_numpy(), 0.0)

    day_index = np.asarray((times.normalize() - times[0].normalize()).days)
    n_days = int(day_index[-1]) + 1
    regimes = np.empty(n_days, dtype=np.int64)
    regimes[0] = rng.choice(3, p=[0.5, 0.3, 0.2])
    for day in range(1, n_days):
        regimes[day] = rng.choice(3, p=_REGIME_TRANSITIONS[regimes[day - 1]])
    daily_clearness = _REGIME_MEAN[regimes] + _REGIME_SPREAD[regimes] * rng.standard_normal(n_days)

    hourly = np.empty(len(times))
    state = 0.0
    for i, shock in enumerate(rng.standard_normal(len(times))):
        state = _HOURLY_AR * state + _HOURLY_SIGMA * np.sqrt(1 - _HOURLY_AR**2) * shock
        hourly[i] = state
    clearness = np.clip(daily_clearness[day_index] + hourly, 0.05, 1.0)
    radiation = np.round(ghi * clearness, 0)

    # Temperature: mean falls with latitude, warms with day of year; diurnal peak near 15:00.
    day_of_year = np.asarray(times.day_of_year, dtype=np.float64)
    seasonal = -np.cos(2 * np.pi * (day_of_year - 15) / 365.25)
    base = 27.0 - 0.45 * max(abs(city.latitude) - 20.0, 0.0) + 9.0 * seasonal * np.sign(city.latitude or 1.0)
    drift = np.cumsum(0.9 * rng.standard_normal(n_days))
    drift -= np.linspace(0.0, drift[-1], n_days)  # keep the month's mean near the climatology
    amplitude = 3.0 + 5.0 * daily_clearness[day_index]
    hour = np.asarray(times.hour, dtype=np.float64)
    diurnal = amplitude * np.sin(2 * np.pi * (hour - 9.0) / 24.0)
    temperature = np.round(base + drift[day_index] + diurnal + 0.4 * rng.standard_normal(len(times)), 1)

    return CityWeather(
        source=SYNTHETIC_SOURCE,
        latitude=city.latitude,
        longitude=city.longitude,
        timezone=timezone,
        time=tuple(t.strftime("%Y-%m-%dT%H:%M") for t in times),
        temperature_2m_C=tuple(float(v) for v in temperature),
        shortwave_radiation_Wm2=tuple(float(v) for v in radiation),
    )


def synthesize_weather(
    cities: Sequence[City], start: str, end: str, seed: int, timezone: str
) -> dict[str, CityWeather]:
    """Synthetic weather for every city over [start, end), deterministic in ``seed``."""
    return {city.name: synthesize_city_weather(city, start, end, seed, timezone) for city in cities}
