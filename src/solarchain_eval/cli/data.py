"""``solarchain-eval data build`` and ``data check``."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path

import typer
from rich.table import Table

from ..common.atomic_files import sha256_file
from ..common.errors import SolarChainError
from ..tasks.dataset import dataset_of
from ..tasks.registry import DEFAULT_TASK, get_task
from ..tasks.suites import get_suite, suite_names
from . import app
from .common import CliError, cli_error, console, progress_bar, reports_errors, say
from .help import HelpGroup

#: The dataset builder of the solar market: the options' choices and defaults are its.
DATASET = dataset_of(get_task(DEFAULT_TASK))
_DEFAULTS = DATASET.defaults

data_app = typer.Typer(help="Build and validate datasets.", cls=HelpGroup, no_args_is_help=True, rich_markup_mode=None)
app.add_typer(data_app, name="data")


#: The --fdia-pattern choices: the builder's false-data patterns (data/fdia.py for the solar market).
FdiaPattern = StrEnum("FdiaPattern", {name: name for name in DATASET.false_data.patterns})
_DEFAULT_PATTERN = FdiaPattern(DATASET.false_data.default_pattern)
_PATTERN_HELP = DATASET.false_data.pattern_help("--fdia-burst-hours")
#: The --weather choices: the builder's weather sources.
WeatherSource = StrEnum("WeatherSource", {name.replace("-", "_"): name for name in DATASET.weather_sources})


def _scenario(rate: float, severity: str | None, pattern: str, burst_hours: int):
    try:
        return DATASET.scenario(rate, severity, pattern, burst_hours)
    except ValueError as error:
        raise CliError(f"--fdia-*: {error}") from None


def _cities(specs: list[str] | None) -> tuple:
    try:
        return DATASET.cities(specs or None)
    except ValueError as error:
        raise cli_error(error) from None


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
    seed: int = typer.Option(_DEFAULTS.seed, help="Seed of the build's random stream."),
    start: str = typer.Option(_DEFAULTS.start, help="First day (local time), YYYY-MM-DD."),
    end: str = typer.Option(_DEFAULTS.end, help="Day after the last one (exclusive), YYYY-MM-DD."),
    nodes_per_city: int = typer.Option(_DEFAULTS.nodes_per_city, min=1, help="PV nodes per city."),
    city: list[str] | None = typer.Option(
        None, "--city", metavar="NAME:LAT:LON", help="A city; repeat for several. Default: the paper's five cities."
    ),
    timezone: str | None = typer.Option(
        None,
        help=f"IANA time zone of the dataset's hours. Default: {_DEFAULTS.timezone}, or with --weather-file the first "
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
        cities, chosen, timezone = _from_weather_files(weather_file, timezone, start, end)
        manifest = _build(chosen, out, cities, seed, start, end, nodes_per_city, timezone, scenario)
        _show_build(manifest, out, seed, len(cities))
        return
    timezone = timezone or _DEFAULTS.timezone
    cities = _cities(city)
    downloads = weather_cache is None and weather is not None and weather.value in DATASET.downloaded_weather_sources
    with progress_bar("downloading weather", len(cities), enabled=downloads) as advance:
        try:
            chosen = DATASET.choose_weather(
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
        except SolarChainError:  # a weather file or answer that cannot be used: reported as it is
            raise
        except ValueError as error:  # dates the synthetic generator cannot cover
            raise cli_error(error) from None
    manifest = _build(chosen, out, cities, seed, start, end, nodes_per_city, timezone, scenario)
    _show_build(manifest, out, seed, len(cities))


def _refuse_existing(out: Path, force: bool) -> None:
    if not force and ((out / DATASET.manifest).exists() or any((out / name).exists() for name in DATASET.files)):
        raise CliError(f"{out} already holds a dataset; pass --force to overwrite it")


def _from_weather_files(specs: list[str], timezone: str | None, start: str, end: str):
    """Cities, weather and time zone of a build from ``--weather-file`` specs (all read and checked
    before anything is written)."""
    read, file_zone = DATASET.read_weather_files(specs)
    zone = timezone or file_zone
    try:
        cities, weather = DATASET.weather_from_files(read, zone, start, end)
    except (ValueError, KeyError) as error:
        if isinstance(error, SolarChainError):  # a weather file that cannot be used: reported as it is
            raise
        raise CliError(f"--weather-file/--start/--end/--timezone: {error}") from None  # a date, zone or city name
    return cities, weather, zone


def _build(chosen, out: Path, cities, seed, start, end, nodes_per_city, timezone, scenario) -> dict:
    """Build the dataset with a progress bar over its nodes; returns its manifest."""
    with progress_bar("building dataset", nodes_per_city * len(cities)) as advance:
        done = [0]

        def on_progress(stage: str, count: int, total: int) -> None:
            if stage == "generation":
                advance(count - done[0])
                done[0] = count

        return DATASET.build(
            chosen,
            out,
            cities=cities,
            seed=seed,
            start=start,
            end=end,
            nodes_per_city=nodes_per_city,
            timezone=timezone,
            scenario=scenario,
            progress=on_progress,
        )


def _show_build(manifest: dict, out: Path, seed: int, n_cities: int) -> None:
    """The files table and the one-line summary of a build."""
    files = manifest["files"]
    table = Table(title=f"dataset written to {out}", title_justify="left")
    table.add_column("file")
    table.add_column("rows", justify="right")
    table.add_column("sha256")
    for name, info in files.items():
        table.add_row(name, f"{info['rows']:,}", info["sha256"])
    console.print(table)
    say(f"weather: {manifest['weather_source']}; seed {seed}; {manifest['hours']} hours; {n_cities} cities", err=False)
    fdia = manifest["fdia"]
    say(f"false data: {fdia['injected_records']:,} records, {fdia['pattern']}, rate {fdia['rate']}", err=False)
    paper_weather = DATASET.paper_weather_sha256
    if paper_weather is not None and manifest.get("weather_sha256") == paper_weather:
        say("weather: the paper's Open-Meteo payload (sha256 matches)", err=False)
    attribution = manifest.get("weather_attribution")
    if attribution:
        say(f"{attribution['attribution']} ({attribution['licence']}, {attribution['licence_url']})", err=False)
    if DATASET.is_published({name: info["sha256"] for name, info in files.items()}):
        say("byte-identical to the paper's published dataset", style="bold green", err=False)


@data_app.command("build-family")
@reports_errors
def build_family(
    family: str = typer.Argument(..., metavar="FAMILY", help="The held-out family: tmy-3sites or paper-cities."),
    out: Path = typer.Option(..., "--out", help="Directory to write one dataset directory per month into."),
    month: list[str] | None = typer.Option(
        None,
        "--month",
        help="A month to build: 1-12 for tmy-3sites, YYYY-MM for paper-cities; repeat for several. "
        "Default: the family's months (tmy-3sites: all twelve; paper-cities: 2026-05 to 2026-10).",
        show_default=False,
    ),
    force: bool = typer.Option(False, "--force", help="Overwrite datasets already in --out."),
    open_meteo_url: str | None = typer.Option(
        None,
        help="Archive endpoint for paper-cities (default: $SOLARCHAIN_OPEN_METEO_URL or the public API).",
    ),
    retries: int = typer.Option(4, min=0, help="Retries per Open-Meteo request (paper-cities)."),
) -> None:
    """Build a held-out dataset family: tmy-3sites offline, paper-cities online once.

    Writes OUT/NAME/ (four CSVs and manifest.json) per month. tmy-3sites (OUT/tmy-3sites-MM/) is
    built from the weather shipped with the package and checked against the sha256s shipped with
    it; a month that differs is not written (exit 2). paper-cities (OUT/paper-cities-YYYY-MM/) is
    the paper's five cities in other months, with Open-Meteo weather fetched once and cached, so a
    rebuild is byte-identical; April 2026, the paper's month, is refused. A failure removes what
    the command wrote. The families' cards are in docs/dataset.md#held-out-family-tmy-3sites and
    docs/dataset.md#held-out-family-paper-cities.
    """
    import shutil
    import time

    datasets = DATASET.family(family, month)
    for dataset in datasets:
        _refuse_existing(out / dataset.name, force)
    began = time.perf_counter()
    table = Table(title=f"{family} written to {out}", title_justify="left")
    for column in ("dataset", "dates", "hours", "sha256 (4 CSVs)"):
        table.add_column(column)
    options = {"open_meteo_url": open_meteo_url, "retries": retries, "notify": say}
    made: list[Path] = []
    new_out = not out.exists()
    try:
        with progress_bar(f"building {family}", len(datasets)) as advance:
            for dataset in datasets:
                target = out / dataset.name
                manifest = DATASET.build_family_member(dataset, target, replace=force, **options)
                made.append(target)
                checked = "match the shipped ones" if dataset.pinned else "in its manifest.json (not pinned)"
                table.add_row(dataset.name, f"{dataset.start} to {dataset.end}", str(manifest["hours"]), checked)
                advance(1)
    except BaseException:
        for target in made:  # nothing half-written: the months this command built go too
            shutil.rmtree(target, ignore_errors=True)
        if new_out and out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        raise
    console.print(table)
    say(f"{len(datasets)} datasets in {time.perf_counter() - began:.1f} s; weather: {datasets[0].weather}", err=False)


@data_app.command("splits")
@reports_errors
def splits() -> None:
    """List the named splits (train, test and the paper's month by start day) and the rule for them.

    The rule for results that claim generality: train and tune on the train split only, report
    the test split (docs/dataset.md#splits).
    """
    table = Table(title="splits", title_justify="left")
    for column in ("split", "role", "datasets", "start days", "suite", "what"):
        table.add_column(column)
    suites: dict[str, list[str]] = {}  # split -> the suites on it alone (evaluate --suite NAME)
    for name in suite_names():
        (only, *more) = get_suite(name).splits
        if not more:
            suites.setdefault(only, []).append(name)
    for split in DATASET.splits():
        names = split.datasets
        shown = names[0] if len(names) == 1 else f"{names[0]} ... {names[-1]} ({len(names)})"
        days = split.start_days
        table.add_row(
            split.name,
            split.role,
            shown,
            "all" if days is None else f"{days[0]}-{days[-1]}",
            ", ".join(suites.get(split.name, [])) or "-",
            split.description,
        )
    console.print(table)
    say(f"rule: {DATASET.split_rule}", err=False)
    say("evaluate an agent on a split: solarchain-eval evaluate --suite SUITE (docs/suites.md)", err=False)


@data_app.command("check")
@reports_errors
def check(data_dir: Path = typer.Argument(..., metavar="DATA_DIR", help="Dataset directory to validate.")) -> None:
    """Validate a dataset directory.

    Checks files, columns, numbers (no NaN or negative power), duplicates, missing hours, statuses
    and the trade window; on a problem prints the file, column and first offending row and exits 2.
    """
    rows = DATASET.check(data_dir)
    summary = Table(title=f"{data_dir}: valid", title_justify="left", show_header=False)
    summary.add_column("what")
    summary.add_column("value", justify="right")
    for what, value in rows:
        summary.add_row(what, value)
    console.print(summary)
    hashes = {name: sha256_file(Path(data_dir) / name) for name in DATASET.files}
    if DATASET.is_published(hashes):
        say("byte-identical to the paper's published dataset", style="bold green", err=False)
