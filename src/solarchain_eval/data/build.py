"""Dataset build: nodes, hourly generation, false-data injection, market and trades (docs/dataset.md).

One ``numpy.random.default_rng(seed)`` stream drives the whole build, consumed in the order
docs/dataset.md lists. With the paper's cached weather and seed 20260511 the four CSVs are
byte-identical to the published ones.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..common.atomic_files import atomic_write_csv, atomic_write_json, sha256_file
from ..common.versions import package_versions
from .cities import City, check_unique_prefixes, factories_for
from .fdia import FDIA_FRACTION, FDIA_MULTIPLIERS, FdiaScenario, inject_false_data  # noqa: F401
from .files import DATASET_FILES, GENERATION_FILE, MANIFEST_FILE, MARKET_FILE, NODES_FILE, TRADES_FILE  # noqa: F401
from .pv import capped_irradiance_wm2, max_power_w, solar_geometry, temperature_factor
from .weather import CityWeather, WeatherError, weather_attribution

INSTALL_FIRST, INSTALL_LAST = dt.date(2020, 1, 1), dt.date(2024, 5, 31)
TRADE_MIN_VERIFIED_MW = 0.002

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class BuildResult:
    out_dir: Path
    manifest: dict


def _noop(stage: str, done: int, total: int) -> None:
    return None


def _build_nodes(rng: np.random.Generator, cities: Sequence[City], nodes_per_city: int) -> pd.DataFrame:
    span_days = (INSTALL_LAST - INSTALL_FIRST).days
    rows = []
    for city in cities:
        for idx in range(1, nodes_per_city + 1):
            latitude = np.round(city.latitude + rng.normal(0, 0.035), 6)
            longitude = np.round(city.longitude + rng.normal(0, 0.035), 6)
            area = np.round(rng.uniform(18, 64), 2)
            efficiency = np.round(rng.uniform(0.176, 0.226), 4)
            temp_coefficient = np.round(rng.uniform(-0.0046, -0.0032), 5)
            install = INSTALL_FIRST + dt.timedelta(days=int(rng.integers(0, span_days)))
            rows.append(
                (
                    f"{city.node_prefix}-{idx:03d}",
                    city.name,
                    latitude,
                    longitude,
                    area,
                    efficiency,
                    temp_coefficient,
                    install.isoformat(),
                )
            )
    columns = [
        "node_id",
        "city",
        "latitude",
        "longitude",
        "panel_area_m2",
        "efficiency",
        "temp_coefficient",
        "install_date",
    ]
    return pd.DataFrame(rows, columns=columns)


@dataclass(frozen=True)
class _CityHours:
    times: pd.DatetimeIndex
    iso: list[str]
    hours: np.ndarray
    irradiance_wm2: np.ndarray
    air_temp_c: np.ndarray


def _city_hours(city: City, weather: CityWeather, start: str, end: str, timezone: str) -> _CityHours:
    local = pd.DatetimeIndex(pd.to_datetime(list(weather.time))).tz_localize(timezone)
    lo, hi = pd.Timestamp(start).tz_localize(timezone), pd.Timestamp(end).tz_localize(timezone)
    keep = np.asarray((local >= lo) & (local < hi))
    times = local[keep]
    if len(times) == 0:
        raise WeatherError(f"weather for {city.name} has no hours in [{start}, {end})")
    expected = pd.date_range(lo, hi, freq="h", inclusive="left")
    if len(times) != len(expected) or not (times == expected).all():
        missing = expected.difference(times)
        first = missing[0].isoformat() if len(missing) else "(duplicates)"
        raise WeatherError(
            f"weather for {city.name} does not cover every hour of [{start}, {end}): first gap at {first}"
        )
    clear_sky, zenith = solar_geometry(city, times)
    observed = np.asarray(weather.shortwave_radiation_Wm2, dtype=np.float64)[keep]
    return _CityHours(
        times=times,
        iso=[t.isoformat() for t in times],
        hours=np.asarray(times.hour, dtype=np.int64),
        irradiance_wm2=capped_irradiance_wm2(observed, clear_sky, zenith),
        air_temp_c=np.asarray(weather.temperature_2m_C, dtype=np.float64)[keep],
    )


def _build_generation(
    rng: np.random.Generator, nodes: pd.DataFrame, hours: Mapping[str, _CityHours], progress: Progress
) -> pd.DataFrame:
    parts = []
    total = len(nodes)
    for i, node in enumerate(nodes.itertuples(index=False)):
        city = hours[node.city]
        n = len(city.iso)
        temp_factor = temperature_factor(node.temp_coefficient, city.air_temp_c)
        # The derate and noise draws alternate per hour, so they must be drawn one at a time.
        derate = np.empty(n)
        noise = np.empty(n)
        uniform, normal = rng.uniform, rng.normal
        for k in range(n):
            derate[k] = uniform(0.965, 0.992)
            noise[k] = normal(1.0, 0.012)
        p_max = max_power_w(city.irradiance_wm2, node.panel_area_m2, node.efficiency, temp_factor)
        reported = p_max * derate * noise
        parts.append(
            pd.DataFrame(
                {
                    "timestamp": city.iso,
                    "hour": city.hours,
                    "node_id": node.node_id,
                    "city": node.city,
                    "latitude": node.latitude,
                    "longitude": node.longitude,
                    "irradiance_Wm2": np.round(city.irradiance_wm2, 2),
                    "air_temp_C": np.round(city.air_temp_c, 2),
                    "P_max_W": np.round(p_max, 2),
                    "P_reported_W": np.round(np.maximum(0.0, reported), 2),
                    "fdia_detected": False,
                    "verification_status": "verified",
                }
            )
        )
        progress("generation", i + 1, total)
    return pd.concat(parts, ignore_index=True)


def _build_market(generation: pd.DataFrame) -> pd.DataFrame:
    order = generation.drop_duplicates("timestamp")[["timestamp", "hour"]]
    verified = generation[generation["verification_status"] == "verified"]
    totals_w = verified.groupby("timestamp", sort=False)["P_reported_W"].sum()
    verified_mw = totals_w.reindex(order["timestamp"], fill_value=0.0).to_numpy() / 1e6
    sc_liquidity = 0.92 * verified_mw + 0.018
    base_liquidity = 0.61 * verified_mw + 0.008
    market = pd.DataFrame(
        {
            "timestamp": order["timestamp"].to_numpy(),
            "hour": order["hour"].to_numpy(),
            "total_verified_MW": np.round(verified_mw, 6),
            "solarchain_liquidity_MW": np.round(sc_liquidity, 6),
            "baseline_liquidity_MW": np.round(base_liquidity, 6),
            "slippage_solarchain_pct": np.round(0.18 / (sc_liquidity + 0.045), 4),
            "slippage_baseline_pct": np.round(0.31 / (base_liquidity + 0.028), 4),
        }
    )
    return market


def _build_trades(rng: np.random.Generator, market: pd.DataFrame, cities: Sequence[City]) -> pd.DataFrame:
    factories = factories_for(tuple(cities))
    active = market[market["total_verified_MW"] > TRADE_MIN_VERIFIED_MW]
    rows = []
    uniform = rng.uniform
    for i, (timestamp, hour, verified_mw, liquidity_mw) in enumerate(
        zip(
            active["timestamp"],
            active["hour"],
            active["total_verified_MW"],
            active["solarchain_liquidity_MW"],
            strict=True,
        )
    ):
        for slot in range(3):
            factory = factories[(i + slot) % len(factories)]
            purchase = min(liquidity_mw * uniform(0.055, 0.16), verified_mw * uniform(0.08, 0.22))
            if purchase <= 0:
                continue
            tokens = np.round(purchase * 1000 * uniform(0.93, 1.08), 4)
            exergy = np.round(purchase * 3600 * uniform(0.015, 0.038), 4)
            rows.append(
                (
                    f"TRD-{len(rows) + 1:05d}",
                    timestamp,
                    hour,
                    factory.factory_id,
                    factory.city,
                    np.round(purchase, 6),
                    tokens,
                    exergy,
                )
            )
    columns = [
        "trade_id",
        "timestamp",
        "hour",
        "factory_id",
        "city",
        "energy_purchased_MW",
        "tokens_burned",
        "exergy_dissipated_MJ",
    ]
    return pd.DataFrame(rows, columns=columns)


def build_dataset(
    weather: Mapping[str, CityWeather],
    out_dir: str | Path,
    *,
    cities: Sequence[City],
    seed: int,
    start: str,
    end: str,
    nodes_per_city: int,
    timezone: str,
    weather_source: str,
    weather_sha256: str | None = None,
    progress: Progress = _noop,
    fdia: FdiaScenario | None = None,
    weather_files: Sequence[Mapping] | None = None,
    attribution: Mapping[str, str] | None = None,
    family: str | None = None,
) -> BuildResult:
    """Build the four dataset CSVs and ``manifest.json`` into ``out_dir``.

    Each file is written atomically and the manifest last, so a directory with a manifest
    is a complete build. ``fdia`` is the false-data injection scenario (default: the paper's,
    5 % of the records, uniform, the paper's multipliers); the manifest records it, and the
    weather's licence attribution when it is third-party data (Open-Meteo, CC BY 4.0).
    A build from standard weather files passes their ``weather_files`` entries (file, format,
    sha256, site, licence) and their ``attribution``, which the manifest records. A dataset of a
    held-out family passes the ``family``'s name, which the manifest records too.
    """
    if nodes_per_city < 1:
        raise ValueError("nodes_per_city must be at least 1")
    check_unique_prefixes(cities)
    missing = [city.name for city in cities if city.name not in weather]
    if missing:
        raise WeatherError(f"no weather for {', '.join(missing)}")
    out = Path(out_dir)
    rng = np.random.default_rng(seed)

    progress("nodes", 0, 1)
    nodes = _build_nodes(rng, cities, nodes_per_city)
    progress("nodes", 1, 1)
    hours = {city.name: _city_hours(city, weather[city.name], start, end, timezone) for city in cities}
    generation = _build_generation(rng, nodes, hours, progress)
    fdia_entry = inject_false_data(rng, generation, fdia)
    market = _build_market(generation)
    trades = _build_trades(rng, market, cities)

    files = {}
    for name, frame in (
        (NODES_FILE, nodes),
        (GENERATION_FILE, generation),
        (MARKET_FILE, market),
        (TRADES_FILE, trades),
    ):
        path = atomic_write_csv(out / name, frame)
        files[name] = {"rows": int(len(frame)), "sha256": sha256_file(path)}
    manifest = {
        "format": "solarchain-eval dataset v1",
        "files": files,
        "seed": int(seed),
        "start": start,
        "end": end,
        "timezone": timezone,
        "nodes_per_city": int(nodes_per_city),
        "cities": [{"name": c.name, "latitude": c.latitude, "longitude": c.longitude} for c in cities],
        "weather_source": weather_source,
        "weather_sha256": weather_sha256,
        "weather_attribution": (
            dict(attribution) if attribution is not None else weather_attribution(weather[c.name] for c in cities)
        ),
        "hours": int(len(market)),
        "fdia": fdia_entry,
        "package_versions": package_versions(),
    }
    if family is not None:
        manifest["family"] = family
    if weather_files is not None:
        manifest["weather_files"] = [dict(entry) for entry in weather_files]
    atomic_write_json(out / MANIFEST_FILE, manifest)
    return BuildResult(out_dir=out, manifest=manifest)
