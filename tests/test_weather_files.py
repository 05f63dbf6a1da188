"""Weather from standard files: field and unit mapping, hour labels, time zones, EPW/PVGIS, bad files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from solarchain_eval.data.weather import WeatherError
from solarchain_eval.data.weather_files import etc_zone, read_weather_file, weather_from_files

pvlib = pytest.importorskip("pvlib")
PVLIB_DATA = Path(pvlib.__file__).parent / "data"
GREENSBORO, SAND_POINT, MIAMI = (PVLIB_DATA / name for name in ("723170TYA.CSV", "703165TY.csv", "12839.tm2"))


def _tmy3_row(path: Path, date: str, time: str) -> dict[str, str]:
    """The raw fields of the TMY3 row of ``date`` (MM/DD, any year) and ``time``, read with the csv module (not pvlib)."""
    import csv

    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    header = rows[1]
    row = next(r for r in rows[2:] if r[0].startswith(date + "/") and r[1] == time)
    return dict(zip(header, row, strict=True))


@pytest.fixture(scope="module")
def greensboro():
    return read_weather_file(GREENSBORO)


@pytest.fixture(scope="module")
def miami():
    from solarchain_eval.data.heldout import read_tmy_files

    return dict(read_tmy_files())["Miami"]  # the same bytes as pvlib's file, read once per process


def test_tmy3_maps_ghi_and_temperature_of_a_known_hour(greensboro):
    raw = _tmy3_row(GREENSBORO, "01/01", "12:00")
    assert (raw["GHI (W/m^2)"], raw["Dry-bulb (C)"]) == ("261", "11.7")
    assert greensboro.format == "tmy3"
    assert greensboro.site.name == "GREENSBORO PIEDMONT TRIAD INT"
    assert (greensboro.site.latitude, greensboro.site.longitude, greensboro.site.elevation_m) == (36.1, -79.95, 273.0)
    assert greensboro.site.utc_offset_h == -5.0
    row = greensboro.hourly.loc[12]  # label 12: the hour ending at 12:00 local standard time, 1 January
    assert row["ghi_Wm2"] == 261.0 and row["temp_air_C"] == 11.7
    assert row["dni_Wm2"] == float(raw["DNI (W/m^2)"]) and row["wind_speed_ms"] == float(raw["Wspd (m/s)"])
    # The build sees the same hour at its true instant: 12:00 UTC-5 is 08:00 UTC-9 and 17:00 UTC.
    at_minus9 = greensboro.city_weather("Etc/GMT+9", "2027-01-01", "2027-01-02")
    assert at_minus9.time[8] == "2027-01-01T08:00" and at_minus9.shortwave_radiation_Wm2[8] == 261.0
    assert at_minus9.temperature_2m_C[8] == 11.7
    in_utc = greensboro.city_weather("UTC", "2027-01-01", "2027-01-02")
    assert in_utc.time[17] == "2027-01-01T17:00" and in_utc.shortwave_radiation_Wm2[17] == 261.0


def test_tmy2_converts_tenths_and_keeps_the_files_hour(miami):
    line = MIAMI.read_text().splitlines()[13]  # header + 12 rows: 1 January, hour 13 (the hour ending 13:00)
    assert line[1:9] == "62010113"
    ghi, tenths_c, tenths_ms = int(line[17:21]), int(line[67:71]), int(line[95:98])
    assert (ghi, tenths_c, tenths_ms) == (145, 189, 41)
    assert miami.format == "tmy2" and miami.site.utc_offset_h == -5
    row = miami.hourly.loc[13]
    assert row["ghi_Wm2"] == ghi
    assert row["temp_air_C"] == pytest.approx(18.9) and row["wind_speed_ms"] == pytest.approx(4.1)
    weather = miami.city_weather("Etc/GMT+5", "2027-01-01", "2027-01-02")
    assert weather.time[13] == "2027-01-01T13:00" and weather.shortwave_radiation_Wm2[13] == 145.0


def test_sand_point_and_the_year_boundary_wrap():
    """Hours a time shift moves before 1 January come from the typical year's 31 December."""
    sand_point = read_weather_file(SAND_POINT)
    assert sand_point.site.utc_offset_h == -9.0 and sand_point.site.name == "SAND POINT"
    noon = _tmy3_row(SAND_POINT, "01/01", "12:00")
    own = sand_point.city_weather("Etc/GMT+9", "2027-01-01", "2027-01-02")
    assert own.shortwave_radiation_Wm2[12] == float(noon["GHI (W/m^2)"]) > 0
    # 1 January 00:00 UTC is 31 December 15:00 at Sand Point (UTC-9): the hour ending then.
    late = _tmy3_row(SAND_POINT, "12/31", "15:00")
    assert float(late["GHI (W/m^2)"]) > 0
    utc = sand_point.city_weather("UTC", "2027-01-01", "2027-01-02")
    assert utc.time[0] == "2027-01-01T00:00"
    assert utc.shortwave_radiation_Wm2[0] == float(late["GHI (W/m^2)"])
    assert utc.temperature_2m_C[0] == float(late["Dry-bulb (C)"])


def test_zones_with_daylight_saving_and_29_february_are_refused(greensboro):
    with pytest.raises(WeatherError, match="America/New_York changes its clock"):
        greensboro.city_weather("America/New_York", "2027-03-01", "2027-04-01")
    with pytest.raises(WeatherError, match="2028-02-29.*no 29 February"):
        greensboro.city_weather("Etc/GMT+5", "2028-02-01", "2028-03-01")
    # A leap year's other days keep their dates: 1 March 2028 12:00 is the file's 1 March 12:00.
    leap = greensboro.city_weather("Etc/GMT+5", "2028-03-01", "2028-03-02")
    same = greensboro.city_weather("Etc/GMT+5", "2027-03-01", "2027-03-02")
    assert leap.shortwave_radiation_Wm2 == same.shortwave_radiation_Wm2


def test_etc_zone_sign():
    assert (etc_zone(-5.0), etc_zone(-9), etc_zone(0), etc_zone(8), etc_zone(5.5)) == (
        "Etc/GMT+5",
        "Etc/GMT+9",
        "UTC",
        "Etc/GMT-8",
        "UTC",
    )


def _epw(path: Path) -> Path:
    """A synthetic EPW file: GHI = 10 x the EPW hour (1-24) in daytime rows, temperature = month + hour / 100."""
    lines = ["LOCATION,Testville,ST,XYZ,Synthetic,000000,45.0,8.0,1.0,250.0"]
    lines += [f"HEADER{i},x" for i in range(7)]
    import datetime as dt

    day = dt.date(2019, 1, 1)
    while day.year == 2019:
        for hour in range(1, 25):
            ghi = 10 * hour if 7 <= hour <= 18 else 0
            fields = [2019, day.month, day.day, hour, 60, "x", f"{day.month + hour / 100:.2f}", 0, 50, 100000]
            fields += [0, 0, 0, ghi, 5, 3, 0, 0, 0, 0, 180, 2.5] + [0] * 13
            lines.append(",".join(str(f) for f in fields))
        day += dt.timedelta(days=1)
    path.write_text("\n".join(lines) + "\n")
    return path


def test_epw_rows_keep_the_hour_the_file_states(tmp_path):
    item = read_weather_file(_epw(tmp_path / "testville.epw"))
    assert item.format == "epw" and item.site.utc_offset_h == 1.0 and item.site.name == "Testville"
    weather = item.city_weather("Etc/GMT-1", "2027-03-05", "2027-03-06")
    assert weather.time[14] == "2027-03-05T14:00"
    assert weather.shortwave_radiation_Wm2[14] == 140.0  # the row of EPW hour 14 (the hour ending 14:00)
    assert weather.temperature_2m_C[14] == pytest.approx(3.14)
    assert item.hourly.loc[14, "wind_speed_ms"] == 2.5 and item.hourly.loc[14, "dni_Wm2"] == 5.0


def _pvgis_rows():
    import datetime as dt

    start = dt.datetime(2007, 1, 1)
    for i in range(8760):
        t = start + dt.timedelta(hours=i)
        yield t, {"T2m": t.month + t.hour / 100, "G(h)": 7.0 * t.hour, "Gb(n)": 1.0, "Gd(h)": 2.0, "WS10m": 3.0}


def test_pvgis_json_and_csv_are_read_at_their_utc_stamps(tmp_path):
    hourly = [{"time(UTC)": t.strftime("%Y%m%d:%H%M"), **values} for t, values in _pvgis_rows()]
    src = {
        "inputs": {"location": {"latitude": 45.0, "longitude": 8.0, "elevation": 250.0}},
        "outputs": {"months_selected": [{"month": m, "year": 2007} for m in range(1, 13)], "tmy_hourly": hourly},
        "meta": {"inputs": {}},
    }
    (tmp_path / "site.json").write_text(json.dumps(src))
    header = ["Latitude (decimal degrees): 45.0", "Longitude (decimal degrees): 8.0", "Elevation (m): 250.0"]
    header += [
        "month,year",
        *(f"{m},2007" for m in range(1, 13)),
        "time(UTC),T2m,RH,G(h),Gb(n),Gd(h),IR(h),WS10m,WD10m,SP",
    ]
    rows = [f"{t:%Y%m%d:%H%M},{v['T2m']:.2f},50,{v['G(h)']},1,2,300,3,180,100000" for t, v in _pvgis_rows()]
    (tmp_path / "site.csv").write_text("\r\n".join([*header, *rows, "T2m: 2-m air temperature"]) + "\r\n")
    for name in ("site.json", "site.csv"):
        item = read_weather_file(tmp_path / name)
        assert item.format == "pvgis" and item.site.utc_offset_h == 0.0 and item.site.latitude == 45.0
        weather = item.city_weather("UTC", "2027-06-10", "2027-06-11")
        assert weather.shortwave_radiation_Wm2[9] == 63.0 and weather.temperature_2m_C[9] == pytest.approx(6.09)


def test_files_give_cities_sites_and_licence(greensboro, miami):
    cities, files = weather_from_files([(None, greensboro), ("Miami", miami)], "Etc/GMT+5", "2027-07-01", "2027-07-02")
    assert [c.name for c in cities] == ["Greensboro Piedmont Triad Int", "Miami"]
    assert (cities[1].latitude, cities[1].longitude) == (25.8, miami.site.longitude)
    assert [e["sha256"] for e in files.entries] == [greensboro.sha256, miami.sha256]
    assert files.entries[1]["site"]["elevation_m"] == 2.0 and files.entries[1]["format"] == "tmy2"
    assert "NREL" in files.attribution["attribution"]
    with pytest.raises(WeatherError, match="second weather file for city 'Miami'"):
        weather_from_files([("Miami", greensboro), ("Miami", miami)], "UTC", "2027-07-01", "2027-07-02")


def _broken_copy(tmp_path: Path, line_number: int, field: int, value: str) -> Path:
    lines = GREENSBORO.read_text().splitlines(keepends=True)
    fields = lines[line_number - 1].split(",")
    fields[field] = value
    lines[line_number - 1] = ",".join(fields)
    path = tmp_path / "bad.csv"
    path.write_text("".join(lines))
    return path


@pytest.mark.parametrize("value", ["-50", "abc"])
def test_a_bad_value_names_the_file_line_and_field_and_writes_nothing(tmp_path, value):
    from typer.testing import CliRunner

    from solarchain_eval.cli import app

    bad = _broken_copy(tmp_path, 1000, 4, value)  # the GHI field of line 1000
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["data", "build", "--out", str(out), "--weather-file", f"Here={bad}"])
    assert result.exit_code == 2, result.output
    message = " ".join(result.output.split())
    assert f"{bad}, line 1000: field 'GHI (W/m^2)' is '{value}', not a number in 0..1500 W/m²" in message
    assert len(result.output.strip().splitlines()) == 1 and not out.exists()


def test_a_missing_row_names_the_line(tmp_path):
    lines = GREENSBORO.read_text().splitlines(keepends=True)
    path = tmp_path / "short.CSV"
    path.write_text("".join(lines[:500] + lines[501:] + lines[-1:]))  # row of line 501 gone, the last one twice
    with pytest.raises(WeatherError, match=r"short.CSV, line 501: the row is for 01-21 20:00, expected 01-21 19:00"):
        read_weather_file(path)


def test_cli_builds_from_weather_files_with_the_sites_in_the_manifest(tmp_path):
    from typer.testing import CliRunner

    from solarchain_eval.cli import app

    out = tmp_path / "gso"
    args = ["data", "build", "--weather-file", f"Greensboro={GREENSBORO}"]
    result = CliRunner().invoke(
        app, [*args, "--out", str(out), "--start", "2027-06-01", "--end", "2027-06-03", "--nodes-per-city", "2"]
    )
    assert result.exit_code == 0, result.output
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["timezone"] == "Etc/GMT+5"  # the file's standard time when --timezone is not given
    assert manifest["cities"] == [{"name": "Greensboro", "latitude": 36.1, "longitude": -79.95}]
    (entry,) = manifest["weather_files"]
    assert entry["file"] == "723170TYA.CSV" and entry["format"] == "tmy3"
    assert entry["site"] == {
        "name": "GREENSBORO PIEDMONT TRIAD INT",
        "latitude": 36.1,
        "longitude": -79.95,
        "elevation_m": 273.0,
        "utc_offset_h": -5.0,
    }
    assert manifest["weather_attribution"]["licence_url"] == "https://www.nrel.gov/disclaimer.html"
    mixed = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "x"), "--weather", "synthetic"])
    assert mixed.exit_code == 2 and "drop --city, --weather and --weather-cache" in mixed.output
    clash = CliRunner().invoke(app, [*args, "--weather-file", f"Greenville={GREENSBORO}", "--out", str(tmp_path / "y")])
    assert clash.exit_code == 2 and "share the node-id prefix 'GRE'" in clash.output
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
