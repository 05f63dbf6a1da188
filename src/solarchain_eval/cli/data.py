"""``solarchain-eval data build`` and ``data check``."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path

import typer
from rich.table import Table

from ..common.atomic_files import sha256_file
from ..data.cities import (
    DEFAULT_END,
    DEFAULT_NODES_PER_CITY,
    DEFAULT_SEED,
    DEFAULT_START,
    DEFAULT_TIMEZONE,
    PAPER_CITIES,
    City,
    check_unique_prefixes,
    parse_city,
)
from ..data.fdia import DEFAULT_FDIA_PATTERN, FDIA_PATTERNS, FdiaError, FdiaScenario, fdia_pattern_help, parse_severity
from ..data.files import DATASET_FILES, MANIFEST_FILE
from ..data.published import PAPER_WEATHER_SHA256, matches_published
from ..data.sources import Weather, WeatherSource, choose_weather
from ..data.weather import WeatherError
from . import app
from .common import CliError, cli_error, console, progress_bar, register_user_error, reports_errors, say
from .help import HelpGroup

data_app = typer.Typer(help="Build and validate datasets.", cls=HelpGroup, no_args_is_help=True, rich_markup_mode=None)
app.add_typer(data_app, name="data")


register_user_error(FdiaError)


#: The --fdia-pattern choices: the patterns of data/fdia.py.
FdiaPattern = StrEnum("FdiaPattern", {name: name for name in FDIA_PATTERNS})
_DEFAULT_PATTERN = FdiaPattern(DEFAULT_FDIA_PATTERN)
_PATTERN_HELP = fdia_pattern_help("--fdia-burst-hours")


def _scenario(rate: float, severity: str | None, pattern: str, burst_hours: int) -> FdiaScenario:
    try:
        return FdiaScenario(
            rate=rate,
            severity=parse_severity(severity) if severity is not None else None,
            pattern=pattern,
            burst_hours=burst_hours,
        )
    except ValueError as error:
        raise CliError(f"--fdia-*: {error}") from None


def _cities(specs: list[str] | None) -> tuple[City, ...]:
    if not specs:
        return PAPER_CITIES
    try:
        cities = tuple(parse_city(spec) for spec in specs)
        check_unique_prefixes(cities)
    except ValueError as error:
        raise cli_error(error) from None
    return cities


@data_app.command("build")
@reports_errors
def build(
    out: Path = typer.Option(..., "--out", help="Directory to write the four CSVs and manifest.json into."),
    weather_cache: Path | None = typer.Option(
        None,
        "--weather-cache",
        help="A cached weather file in the paper's layout (e.g. the paper's cached Open-Meteo weather).",
    ),
    weather: WeatherSource | None = typer.Option(
        None,
        "--weather",
        help="Weather source when no --weather-cache is given: 'paper' (the paper's Open-Meteo payload, shipped with "
        "the package; the paper's cities and April 2026 only), 'synthetic' (offline, pvlib clear sky with seeded "
        "clouds) or 'open-meteo' (live archive API; the payload is cached in the user cache directory). "
        "Default: 'paper' when it covers the cities and dates, else 'synthetic'.",
        show_default=False,
    ),
    seed: int = typer.Option(DEFAULT_SEED, help="Seed of the build's random stream."),
    start: str = typer.Option(DEFAULT_START, help="First day (local time), YYYY-MM-DD."),
    end: str = typer.Option(DEFAULT_END, help="Day after the last one (exclusive), YYYY-MM-DD."),
    nodes_per_city: int = typer.Option(DEFAULT_NODES_PER_CITY, min=1, help="PV nodes per city."),
    city: list[str] | None = typer.Option(
        None, "--city", metavar="NAME:LAT:LON", help="A city; repeat for several. Default: the paper's five cities."
    ),
    timezone: str | None = typer.Option(
        None,
        help=f"IANA time zone of the dataset's hours. Default: {DEFAULT_TIMEZONE}, or with --weather-file the first "
        "file's standard time as a fixed-offset zone (Etc/GMT+5 is UTC-5).",
        show_default=False,
    ),
    weather_file: list[str] | None = typer.Option(
        None,
        "--weather-file",
        metavar="[CITY=]FILE",
        help="A TMY3 (.csv), TMY2 (.tm2), EPW (.epw) or PVGIS typical-year (.csv, .json) file; repeat for several. "
        "Each file is one city at the file's site, named CITY or after the site; replaces --city, --weather and "
        "--weather-cache (docs/dataset.md#weather-from-standard-files).",
    ),
    open_meteo_url: str | None = typer.Option(
        None, help="Archive endpoint for --weather open-meteo (default: $SOLARCHAIN_OPEN_METEO_URL or the public API)."
    ),
    refresh_weather: bool = typer.Option(False, help="Re-download Open-Meteo weather even if it is cached."),
    retries: int = typer.Option(4, min=0, help="Retries per Open-Meteo request (exponential back-off from 1 s)."),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing dataset in --out."),
    fdia_rate: float = typer.Option(
        0.05, "--fdia-rate", min=0.0, max=1.0, help="Fraction of generation records injected with false data."
    ),
    fdia_severity: str | None = typer.Option(
        None,
        "--fdia-severity",
        metavar="LO:HI",
        help="Injection multiplier range: an injected daylight reading is P_max x uniform(LO, HI) "
        "(default: the paper's multipliers 0.42, 1.38, 1.55, 1.82).",
    ),
    fdia_pattern: FdiaPattern = typer.Option(_DEFAULT_PATTERN, "--fdia-pattern", help=_PATTERN_HELP),
    fdia_burst_hours: int = typer.Option(6, "--fdia-burst-hours", min=1, help="Hours per clustered burst."),
) -> None:
    """Build a dataset: nodes, hourly PV generation, false-data injection, market, trades.

    Writes the four CSVs and manifest.json (row counts, sha256, seed, weather source and its
    licence attribution, versions). With the defaults (data build --out DIR) the weather is the
    paper's Open-Meteo payload shipped with the package and the four CSVs are byte-identical to
    the paper's published dataset. The --fdia-* options choose the attack scenario, which the
    manifest records (docs/dataset.md#attack-scenarios).
    """
    scenario = _scenario(fdia_rate, fdia_severity, fdia_pattern.value, fdia_burst_hours)
    _refuse_existing(out, force)
    if weather_file:
        if city or weather_cache is not None or weather is not None:
            raise CliError(
                "--weather-file gives the cities and their weather: drop --city, --weather and --weather-cache"
            )
        cities, chosen, timezone, files = _from_weather_files(weather_file, timezone, start, end)
        result = _build(chosen, out, cities, seed, start, end, nodes_per_city, timezone, scenario, files)
        _show_build(result, out, chosen.source, seed, len(cities))
        return
    timezone = timezone or DEFAULT_TIMEZONE
    cities = _cities(city)
    downloads = weather_cache is None and weather is WeatherSource.open_meteo
    with progress_bar("downloading weather", len(cities), enabled=downloads) as advance:
        try:
            chosen = choose_weather(
                cities,
                start,
                end,
                seed=seed,
                timezone=timezone,
                weather_cache=weather_cache,
                source=weather,
                open_meteo_url=open_meteo_url,
                refresh=refresh_weather,
                retries=retries,
                on_city=lambda _name: advance(1),
                notify=say,
            )
        except WeatherError:
            raise
        except ValueError as error:  # dates the synthetic generator cannot cover
            raise cli_error(error) from None
    result = _build(chosen, out, cities, seed, start, end, nodes_per_city, timezone, scenario)
    _show_build(result, out, chosen.source, seed, len(cities))


def _refuse_existing(out: Path, force: bool) -> None:
    if not force and ((out / MANIFEST_FILE).exists() or any((out / name).exists() for name in DATASET_FILES)):
        raise CliError(f"{out} already holds a dataset; pass --force to overwrite it")


def _from_weather_files(specs: list[str], timezone: str | None, start: str, end: str):
    """Cities, weather, time zone and file weather of a build from ``--weather-file`` specs (all read
    and checked before anything is written)."""
    from ..data.weather_files import etc_zone, parse_weather_file_spec, read_weather_file, weather_from_files

    read = []
    for spec in specs:
        name, path = parse_weather_file_spec(spec)
        read.append((name, read_weather_file(path)))
    zone = timezone or etc_zone(read[0][1].site.utc_offset_h)
    try:
        cities, files = weather_from_files(read, zone, start, end)
        check_unique_prefixes(cities)
    except (ValueError, KeyError) as error:
        if isinstance(error, WeatherError):
            raise
        raise CliError(f"--weather-file/--start/--end/--timezone: {error}") from None  # a date, zone or city name
    return cities, Weather(files.payload, files.source, files.sha256), zone, files


def _build(
    chosen: Weather, out: Path, cities, seed, start, end, nodes_per_city, timezone, scenario: FdiaScenario, files=None
):
    """Build the dataset with a progress bar over its nodes."""
    from ..data.build import build_dataset

    with progress_bar("building dataset", nodes_per_city * len(cities)) as advance:
        done = [0]

        def on_progress(stage: str, count: int, total: int) -> None:
            if stage == "generation":
                advance(count - done[0])
                done[0] = count

        return build_dataset(
            chosen.payload,
            out,
            cities=cities,
            seed=seed,
            start=start,
            end=end,
            nodes_per_city=nodes_per_city,
            timezone=timezone,
            weather_source=chosen.source,
            weather_sha256=chosen.sha256,
            progress=on_progress,
            fdia=scenario,
            weather_files=files.entries if files is not None else None,
            attribution=files.attribution if files is not None else None,
        )


def _show_build(result, out: Path, source: str, seed: int, n_cities: int) -> None:
    """The files table and the one-line summary of a build."""
    files = result.manifest["files"]
    table = Table(title=f"dataset written to {out}", title_justify="left")
    table.add_column("file")
    table.add_column("rows", justify="right")
    table.add_column("sha256")
    for name, info in files.items():
        table.add_row(name, f"{info['rows']:,}", info["sha256"])
    console.print(table)
    say(f"weather: {source}; seed {seed}; {result.manifest['hours']} hours; {n_cities} cities", err=False)
    fdia = result.manifest["fdia"]
    say(f"false data: {fdia['injected_records']:,} records, {fdia['pattern']}, rate {fdia['rate']}", err=False)
    if result.manifest.get("weather_sha256") == PAPER_WEATHER_SHA256:
        say("weather: the paper's Open-Meteo payload (sha256 matches)", err=False)
    attribution = result.manifest.get("weather_attribution")
    if attribution:
        say(f"{attribution['attribution']} ({attribution['licence']}, {attribution['licence_url']})", err=False)
    if matches_published({name: info["sha256"] for name, info in files.items()}):
        say("byte-identical to the paper's published dataset", style="bold green", err=False)


@data_app.command("build-family")
@reports_errors
def build_family(
    family: str = typer.Argument(..., metavar="FAMILY", help="The held-out family: tmy-3sites."),
    out: Path = typer.Option(..., "--out", help="Directory to write one dataset directory per month into."),
    month: list[int] | None = typer.Option(
        None, "--month", min=1, max=12, help="A month to build (1-12); repeat for several. Default: all twelve."
    ),
    force: bool = typer.Option(False, "--force", help="Overwrite datasets already in --out."),
) -> None:
    """Build a held-out dataset family offline from the weather shipped with the package.

    Writes OUT/FAMILY-MM/ (four CSVs and manifest.json) per month and checks each against the
    sha256s shipped with the package; a month that differs is not written (exit 2). The family's
    design and licence are in docs/dataset.md#held-out-family-tmy-3sites.
    """
    import time

    from ..data.heldout import build_checked, heldout_dataset

    datasets = [heldout_dataset(family, m) for m in (sorted(set(month)) if month else range(1, 13))]
    for dataset in datasets:
        _refuse_existing(out / dataset.name, force)
    began = time.perf_counter()
    table = Table(title=f"{family} written to {out}", title_justify="left")
    for column in ("dataset", "dates", "hours", "sha256 (4 CSVs)"):
        table.add_column(column)
    with progress_bar(f"building {family}", len(datasets)) as advance:
        for dataset in datasets:
            target = build_checked(dataset, out / dataset.name, replace=force)
            hours = json.loads((target / MANIFEST_FILE).read_text(encoding="utf-8"))["hours"]
            table.add_row(dataset.name, f"{dataset.start} to {dataset.end}", str(hours), "match the shipped ones")
            advance(1)
    console.print(table)
    say(
        f"{len(datasets)} datasets in {time.perf_counter() - began:.1f} s; weather: public NREL data (NSRDB)", err=False
    )


@data_app.command("splits")
@reports_errors
def splits() -> None:
    """List the named splits (train, test and the paper's month by start day) and the rule for them.

    The rule for results that claim generality: train and tune on the train split only, report
    the test split (docs/dataset.md#splits).
    """
    from ..data.splits import SPLIT_RULE, SPLITS

    table = Table(title="splits", title_justify="left")
    for column in ("split", "role", "datasets", "start days", "what"):
        table.add_column(column)
    for split in SPLITS.values():
        names = split.datasets
        shown = names[0] if len(names) == 1 else f"{names[0]} ... {names[-1]} ({len(names)})"
        days = {entry.start_days for entry in split.entries}
        (first,) = days
        table.add_row(
            split.name, split.role, shown, "all" if first is None else f"{first[0]}-{first[-1]}", split.description
        )
    console.print(table)
    say(f"rule: {SPLIT_RULE}", err=False)


@data_app.command("check")
@reports_errors
def check(data_dir: Path = typer.Argument(..., metavar="DATA_DIR", help="Dataset directory to validate.")) -> None:
    """Validate a dataset directory.

    Checks files, columns, numbers (no NaN or negative power), duplicates, missing hours, statuses
    and the trade window; on a problem prints the file, column and first offending row and exits 2.
    """
    from ..data.load import load_raw_dataset
    from ..data.table import table_from_raw

    raw = load_raw_dataset(data_dir)
    table = table_from_raw(raw)
    gen = raw.generation
    summary = Table(title=f"{data_dir}: valid", title_justify="left", show_header=False)
    summary.add_column("what")
    summary.add_column("value", justify="right")
    summary.add_row("hours", f"{raw.hours:,} from {raw.first_timestamp.isoformat()}")
    summary.add_row("cities", ", ".join(table.cities))
    summary.add_row("nodes", f"{gen['node_id'].nunique():,}")
    summary.add_row("generation records", f"{len(gen):,}")
    summary.add_row("FDIA-labelled records", f"{int(gen['fdia_detected'].sum()):,}")
    summary.add_row("rejected records", f"{int((~gen['verified']).sum()):,}")
    summary.add_row("trades", f"{len(raw.trades):,}")
    summary.add_row("mean raw violation rate ν", f"{table.raw_violation_rate.mean():.4f}")
    console.print(summary)
    hashes = {name: sha256_file(Path(data_dir) / name) for name in DATASET_FILES}
    if matches_published(hashes):
        say("byte-identical to the paper's published dataset", style="bold green", err=False)
