"""Weather from standard files: TMY3, TMY2, EPW and PVGIS typical-year files (docs/dataset.md#weather-from-standard-files).

Each file is parsed by ``pvlib.iotools`` and mapped to SI units; the build uses two of its
quantities, global horizontal irradiance (the pipeline's ``shortwave_radiation_Wm2``) and air
temperature (``temperature_2m_C``). The other three (DNI, DHI, wind speed) are read and converted
for callers, not used by the build.

Time. Every file holds one typical year of 8,760 hours on a 365-day calendar. A row is labelled
by the end of its hour, the convention of the paper's Open-Meteo payload (the value at ``T`` is
the mean over the hour ending at ``T``): TMY3 files are already labelled so; pvlib labels TMY2 and
EPW rows by the start of their hour, so their labels move one hour later, back to the hour the
file states; PVGIS rows are taken at their UTC stamp. TMY3, TMY2 and EPW hours are local standard
time at the UTC offset of the file's header (no daylight-saving time). For a build the typical
year is laid on every calendar year the build touches, at the true instant of each hour, and the
hours are then written as wall-clock times of the build's time zone; a 29 February has no
weather in a typical year.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .cities import City
from .weather import CityWeather, WeatherError

FORMATS = ("tmy3", "tmy2", "epw", "pvgis")
HOURS_PER_YEAR = 8760
#: Columns of :attr:`WeatherFile.hourly`, each in the unit its name ends with.
COLUMNS = ("ghi_Wm2", "dni_Wm2", "dhi_Wm2", "temp_air_C", "wind_speed_ms")
#: Plausible ranges of the two quantities the build uses; a value outside names its row.
_REQUIRED_RANGES = {"ghi_Wm2": (0.0, 1500.0), "temp_air_C": (-90.0, 65.0)}
_UNITS = {"ghi_Wm2": "W/m²", "temp_air_C": "°C"}
#: Other quantities outside these ranges are the formats' missing-value codes; they become NaN.
_OPTIONAL_RANGES = {"dni_Wm2": (0.0, 1500.0), "dhi_Wm2": (0.0, 1500.0), "wind_speed_ms": (0.0, 100.0)}

#: Per format: the file's field (as pvlib names it) and factor to SI of each quantity, hours added to pvlib's labels.
_MAPPING = {
    "tmy3": ({"ghi_Wm2": ("GHI (W/m^2)", 1.0), "dni_Wm2": ("DNI (W/m^2)", 1.0), "dhi_Wm2": ("DHI (W/m^2)", 1.0),
              "temp_air_C": ("Dry-bulb (C)", 1.0), "wind_speed_ms": ("Wspd (m/s)", 1.0)}, 0),
    # TMY2 stores temperature and wind speed in tenths of °C and of m/s.
    "tmy2": ({"ghi_Wm2": ("GHI", 1.0), "dni_Wm2": ("DNI", 1.0), "dhi_Wm2": ("DHI", 1.0),
              "temp_air_C": ("DryBulb", 0.1), "wind_speed_ms": ("Wspd", 0.1)}, 1),
    "epw": ({"ghi_Wm2": ("ghi", 1.0), "dni_Wm2": ("dni", 1.0), "dhi_Wm2": ("dhi", 1.0),
             "temp_air_C": ("temp_air", 1.0), "wind_speed_ms": ("wind_speed", 1.0)}, 1),
    "pvgis": ({"ghi_Wm2": ("G(h)", 1.0), "dni_Wm2": ("Gb(n)", 1.0), "dhi_Wm2": ("Gd(h)", 1.0),
               "temp_air_C": ("T2m", 1.0), "wind_speed_ms": ("WS10m", 1.0)}, 0),
}  # fmt: skip

#: What the manifest says of each format's source fields (hourly irradiation in Wh/m² over the
#: hour is numerically the hour's mean irradiance in W/m²).
FIELD_NOTES = {
    "tmy3": {"shortwave_radiation_Wm2": "GHI (Wh/m2 over the hour ending at the stamp)", "temperature_2m_C": "Dry-bulb (C)"},
    "tmy2": {"shortwave_radiation_Wm2": "GHI (Wh/m2 over the hour ending at the stamp)",
             "temperature_2m_C": "DryBulb (tenths of C) / 10"},
    "epw": {"shortwave_radiation_Wm2": "Global Horizontal Radiation (Wh/m2 over the hour ending at the stamp)",
            "temperature_2m_C": "Dry Bulb Temperature (C)"},
    "pvgis": {"shortwave_radiation_Wm2": "G(h) (W/m2 at the UTC stamp)", "temperature_2m_C": "T2m (C)"},
}  # fmt: skip

_NREL = {
    "attribution": "Typical meteorological year data of the National Solar Radiation Data Base (NSRDB), "
    "National Renewable Energy Laboratory (NREL), U.S. Department of Energy",
    "source_url": "https://nsrdb.nrel.gov/",
    "licence": "public NREL data (U.S. Department of Energy); no licence terms in the file",
    "licence_url": "https://www.nrel.gov/disclaimer.html",
}
#: Licence attribution recorded per format (EPW files come from many publishers).
LICENCES = {
    "tmy3": _NREL,
    "tmy2": _NREL,
    "epw": {
        "attribution": "EnergyPlus weather (EPW) file; its publisher is not recorded in the file",
        "source_url": "",
        "licence": "as stated by the file's publisher",
        "licence_url": "",
    },
    "pvgis": {
        "attribution": "PVGIS (c) European Union, 2001-2026",
        "source_url": "https://joint-research-centre.ec.europa.eu/photovoltaic-geographical-information-system-pvgis_en",
        "licence": "reuse authorised provided the source is acknowledged (European Commission reuse policy)",
        "licence_url": "https://commission.europa.eu/legal-notice_en",
    },
}


@dataclass(frozen=True)
class Site:
    """Where a weather file was measured: name, decimal degrees (WGS84), metres and hours east of UTC."""

    name: str
    latitude: float
    longitude: float
    elevation_m: float
    utc_offset_h: float

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "latitude": self.latitude,
            "longitude": self.longitude,
            "elevation_m": self.elevation_m,
            "utc_offset_h": self.utc_offset_h,
        }


@dataclass(frozen=True)
class WeatherFile:
    """One typical year read from a standard file.

    Attributes
    ----------
    path : Path
    format : str
        One of :data:`FORMATS`.
    sha256 : str
        Of the file's bytes.
    site : Site
    hourly : pandas.DataFrame
        The :data:`COLUMNS`, one row per hour of the year in file order, indexed by the row's label in
        hours after 1 January 00:00 of the file's clock (local standard time; UTC for PVGIS): 1..8760
        for hour-ending formats, 0..8759 for PVGIS.
    """

    path: Path
    format: str
    sha256: str
    site: Site
    hourly: pd.DataFrame

    @property
    def licence(self) -> dict[str, str]:
        return dict(LICENCES[self.format])

    def utc_instants(self, year: int) -> pd.DatetimeIndex:
        """The rows' labels laid on calendar ``year`` (month, day and hour kept), as UTC instants.

        In a leap year the rows keep their dates, so 29 February has no row.
        """
        reference = pd.Timestamp(2027, 1, 1) + pd.to_timedelta(self.hourly.index.to_numpy(), unit="h")
        years = year + (np.asarray(reference.year) - 2027)
        local = pd.to_datetime(
            pd.DataFrame({"year": years, "month": reference.month, "day": reference.day, "hour": reference.hour})
        )
        offset = dt.timezone(dt.timedelta(hours=self.site.utc_offset_h))
        return pd.DatetimeIndex(local).tz_localize(offset).tz_convert("UTC")

    def city_weather(self, timezone: str, start: str, end: str) -> CityWeather:
        """The weather of the hours ``[start, end)`` (dates in ``timezone``) as the build reads it.

        Raises
        ------
        WeatherError
            An hour of the range has no weather (29 February) or ``timezone`` changes its clock
            (daylight-saving time) inside the range.
        """
        first, stop = dt.date.fromisoformat(start), dt.date.fromisoformat(end)
        lo, hi = pd.Timestamp(first).tz_localize(timezone), pd.Timestamp(stop).tz_localize(timezone)
        years = [self.utc_instants(y) for y in range(first.year - 1, stop.year + 1)]
        instants = years[0].append(years[1:])
        frame = pd.concat([self.hourly] * (stop.year - first.year + 2), ignore_index=True)
        frame.index = instants.tz_convert(timezone)
        wanted = pd.date_range(lo, hi, freq="h", inclusive="left")
        missing = wanted.difference(frame.index)
        if len(missing):
            why = (
                " (a typical year has no 29 February)"
                if (missing.month == 2).any() and (missing.day == 29).any()
                else ""
            )
            raise WeatherError(f"{self.path}: no weather for {missing[0].isoformat()}{why}")
        picked = frame.loc[wanted]
        if len({t.utcoffset() for t in wanted}) > 1:
            raise WeatherError(
                f"time zone {timezone} changes its clock between {start} and {end}; the dataset's hours are wall-clock "
                "hours, so use a zone without daylight-saving time (e.g. Etc/GMT+5 for UTC-5, or UTC)"
            )
        wall = [t.strftime("%Y-%m-%dT%H:%M") for t in wanted]
        return CityWeather(
            source=f"{self.format.upper()} file {self.path.name} ({self.site.name})",
            latitude=self.site.latitude,
            longitude=self.site.longitude,
            timezone=timezone,
            time=tuple(wall),
            temperature_2m_C=tuple(float(v) for v in picked["temp_air_C"]),
            shortwave_radiation_Wm2=tuple(float(v) for v in picked["ghi_Wm2"]),
        )

    def manifest_entry(self, city: str) -> dict:
        """What a build's manifest records of this file (``weather_files``)."""
        return {
            "city": city,
            "file": self.path.name,
            "format": self.format,
            "sha256": self.sha256,
            "site": self.site.to_json(),
            "fields": dict(FIELD_NOTES[self.format]),
            "hour_label": "end of the hour" if self.format != "pvgis" else "the file's UTC stamp",
            "licence": self.licence,
        }


def detect_format(path: Path) -> str:
    """The format of ``path`` from its suffix (and, for ``.csv``, its first line)."""
    suffix = path.suffix.lower()
    if suffix == ".tm2":
        return "tmy2"
    if suffix == ".epw":
        return "epw"
    if suffix == ".json":
        return "pvgis"
    if suffix == ".csv":
        with path.open("rb") as handle:
            first = handle.readline()
        return "pvgis" if first.lower().startswith(b"latitude") else "tmy3"
    raise WeatherError(
        f"{path}: unknown weather file type '{path.suffix}' (expected .csv TMY3 or PVGIS, .tm2, .epw, .json)"
    )


def _pvgis_first_data_line(path: Path) -> int:
    with path.open("rb") as handle:
        for number, line in enumerate(handle, 1):
            if line.startswith(b"time(UTC)"):
                return number + 1
    return 1


def _row_namer(path: Path, fmt: str):
    """Row index -> where it is in the file (a line number; an array entry for PVGIS JSON)."""
    if fmt == "pvgis" and path.suffix.lower() == ".json":
        return lambda i: f"tmy_hourly[{i}]"
    first = {"tmy3": 3, "tmy2": 2, "epw": 9}.get(fmt) or _pvgis_first_data_line(path)
    return lambda i: f"line {first + i}"


def _parse(path: Path, fmt: str) -> tuple[pd.DataFrame, Site]:
    with warnings.catch_warnings():  # pandas' mixed-type warning on a bad field: the check below names it
        warnings.simplefilter("ignore", pd.errors.DtypeWarning)
        return _parse_quietly(path, fmt)


def _parse_quietly(path: Path, fmt: str) -> tuple[pd.DataFrame, Site]:
    from pvlib import iotools

    if fmt == "tmy3":
        data, meta = iotools.read_tmy3(str(path), map_variables=False)
        name = str(meta["Name"]).strip('"')
        site = Site(name, meta["latitude"], meta["longitude"], meta["altitude"], meta["TZ"])
    elif fmt == "tmy2":
        data, meta = iotools.read_tmy2(str(path))
        site = Site(str(meta["City"]).strip(), meta["latitude"], meta["longitude"], meta["altitude"], meta["TZ"])
    elif fmt == "epw":
        data, meta = iotools.read_epw(str(path))
        site = Site(str(meta["city"]).strip(), meta["latitude"], meta["longitude"], meta["altitude"], meta["TZ"])
    else:
        data, meta = iotools.read_pvgis_tmy(str(path), map_variables=False)
        location = meta["inputs"].get("location", meta["inputs"])
        site = Site(path.stem, location["latitude"], location["longitude"], location["elevation"], 0.0)
    return data, site


def read_weather_file(path: str | Path, fmt: str | None = None) -> WeatherFile:
    """Read a TMY3, TMY2, EPW or PVGIS (CSV or JSON) typical-year file with ``pvlib.iotools``.

    Raises
    ------
    WeatherError
        The file is missing or unreadable, lacks a field, has not 8,760 hourly rows in calendar
        order, or has a GHI or temperature that is not a plausible number; the message names
        the file and, where it can, the field and the line.
    """
    path = Path(path)
    if not path.is_file():
        raise WeatherError(f"weather file not found: {path}")
    fmt = fmt or detect_format(path)
    if fmt not in FORMATS:
        raise WeatherError(f"{path}: unknown weather file format '{fmt}' (one of {', '.join(FORMATS)})")
    try:
        data, site = _parse(path, fmt)
    except WeatherError:
        raise
    except Exception as error:  # pvlib reports malformed files with many exception types
        first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise WeatherError(f"{path}: not a readable {fmt.upper()} file ({first})") from None
    where = _row_namer(path, fmt)
    if len(data) != HOURS_PER_YEAR:
        raise WeatherError(f"{path}: {len(data)} hourly rows; a typical-year file has {HOURS_PER_YEAR}")
    columns, shift = _MAPPING[fmt]
    hourly = pd.DataFrame(index=pd.RangeIndex(len(data)))
    for name, (column, factor) in columns.items():
        if column not in data.columns:
            if name in _REQUIRED_RANGES:
                raise WeatherError(f"{path}: no '{column}' field")
            hourly[name] = np.nan
            continue
        values = pd.to_numeric(data[column], errors="coerce").to_numpy(dtype=np.float64) * factor
        low, high = _REQUIRED_RANGES.get(name) or _OPTIONAL_RANGES[name]
        bad = ~np.isfinite(values) | (values < low) | (values > high)
        if name in _REQUIRED_RANGES and bad.any():
            i = int(np.argmax(bad))
            raise WeatherError(
                f"{path}, {where(i)}: field '{column}' is '{data[column].iloc[i]}', not a number in "
                f"{low:g}..{high:g} {_UNITS[name]} (after unit conversion)"
            )
        hourly[name] = np.where(bad, np.nan, values)
    hourly.index = _labels(path, fmt, data.index, shift, where)
    return WeatherFile(path, fmt, hashlib.sha256(path.read_bytes()).hexdigest(), site, hourly)


def _labels(path: Path, fmt: str, index: pd.Index, shift: int, where) -> pd.Index:
    """Each row's label in hours from 1 January 00:00, after checking the rows run hour by hour through one
    365-day year (the file's year is ignored: a typical year mixes years)."""
    first = 0 if fmt == "pvgis" else 1
    labels = np.arange(first, first + HOURS_PER_YEAR)
    expected = pd.Timestamp(2027, 1, 1) + pd.to_timedelta(labels, unit="h")
    stamps = pd.DatetimeIndex(index).tz_localize(None) + pd.Timedelta(hours=shift)
    same = (
        (np.asarray(stamps.month) == np.asarray(expected.month))
        & (np.asarray(stamps.day) == np.asarray(expected.day))
        & (np.asarray(stamps.hour) == np.asarray(expected.hour))
    )
    if not same.all():
        i = int(np.argmin(same))
        raise WeatherError(
            f"{path}, {where(i)}: the row is for {stamps[i].strftime('%m-%d %H:00')}, expected "
            f"{expected[i].strftime('%m-%d %H:00')} (one row per hour of a 365-day year, in order)"
        )
    return pd.Index(labels, name="label_h")


def etc_zone(utc_offset_h: float) -> str:
    """The IANA fixed-offset zone of a whole-hour UTC offset (``Etc/GMT+5`` is UTC-5), else ``UTC``."""
    if utc_offset_h != int(utc_offset_h):
        return "UTC"
    hours = -int(utc_offset_h)
    return "UTC" if hours == 0 else f"Etc/GMT{hours:+d}"


@dataclass(frozen=True)
class FileWeather:
    """The weather of a build from standard files, as :func:`weather_from_files` returns it.

    ``payload``/``source``/``sha256`` are what :class:`~solarchain_eval.data.sources.Weather` holds;
    ``entries`` the manifest's ``weather_files``; ``attribution`` its ``weather_attribution``.
    """

    payload: dict[str, CityWeather]
    source: str
    sha256: str
    entries: list[dict]
    attribution: dict[str, str]


def parse_weather_file_spec(text: str) -> tuple[str | None, Path]:
    """``CITY=FILE`` -> (CITY, FILE); a bare ``FILE`` -> (None, FILE) (the file's site names the city)."""
    name, sep, rest = text.partition("=")
    if sep and name.strip() and "/" not in name and rest:
        return name.strip(), Path(rest)
    return None, Path(text)


def city_name(site: Site) -> str:
    """A city name from a site's name: its words title-cased (``"SAND POINT"`` -> ``"Sand Point"``)."""
    return " ".join(word.capitalize() for word in site.name.replace('"', "").split()) or "Site"


def weather_from_files(
    files: Sequence[tuple[str | None, WeatherFile]], timezone: str, start: str, end: str
) -> tuple[tuple[City, ...], FileWeather]:
    """The cities (at the files' sites) and the weather of a build from ``(name or None, file)`` pairs."""
    cities, payload, entries = [], {}, []
    for name, item in files:
        city = City(name or city_name(item.site), item.site.latitude, item.site.longitude)
        if city.name in payload:
            raise WeatherError(f"{item.path}: a second weather file for city '{city.name}'")
        cities.append(city)
        payload[city.name] = item.city_weather(timezone, start, end)
        entries.append(item.manifest_entry(city.name))
    digest = hashlib.sha256("".join(f"{e['sha256']}  {e['city']}={e['file']}\n" for e in entries).encode()).hexdigest()
    licences = {e["licence"]["attribution"]: e["licence"] for e in entries}
    attribution = next(iter(licences.values())) if len(licences) == 1 else {
        key: "; ".join(dict.fromkeys(item[key] for item in licences.values() if item[key]))
        for key in ("attribution", "source_url", "licence", "licence_url")
    }  # fmt: skip
    names = ", ".join(f"{e['city']}={e['file']} ({e['format'].upper()})" for e in entries)
    return tuple(cities), FileWeather(payload, f"weather files: {names}", digest, entries, dict(attribution))
