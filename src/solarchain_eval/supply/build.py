"""The supply-chain dataset builder: seeded, byte-reproducible (docs/tasks/supply_chain.md#dataset).

One seed gives the same three CSVs and manifest byte for byte: the regions' parameters
(:mod:`.files`), each region's daily retailer orders (Poisson around a weekly and annual season,
with promotions and shocks) or a user's own demand file, and the spoofed inventory reports. The
attack reuses the solar dataset's scenario (:class:`~solarchain_eval.data.fdia.FdiaScenario`:
rate, severity, ``uniform`` / ``clustered`` / ``stealthy``) on the (day, region) report records:
an injected report shows ``m x warehouse capacity`` units, and a stealthy one ``min(m, 1) x``
capacity, which the capacity check cannot see. Every input is checked before anything is written.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from ..common.atomic_files import atomic_write_text, sha256_file
from ..common.errors import OptionsError
from ..data.errors import DatasetError
from ..data.fdia import FDIA_MULTIPLIERS, FdiaScenario
from . import files as f

#: The columns of a user's demand file (docs/tasks/supply_chain.md#bring-your-own-demand).
USER_DEMAND_COLUMNS = ("date", "region", "orders_units")
MAX_ORDERS_UNITS = 1e9
MAX_DAYS = 36_600  # a century of days


class SupplyBuildError(OptionsError, ValueError):
    """A build option (days, start date) that is out of range or malformed."""


def _season(days: int, start: dt.date) -> np.ndarray:
    dates = [start + dt.timedelta(days=d) for d in range(days)]
    weekday = np.array([f.WEEKDAY_FACTORS[x.weekday()] for x in dates])
    doy = np.array([x.timetuple().tm_yday for x in dates], dtype=np.float64)
    annual = 1.0 + f.ANNUAL_AMPLITUDE * np.cos(2.0 * np.pi * (doy - 350.0) / 365.25)
    return weekday * annual


def _windows(rng: np.random.Generator, days: int, probability: float, length: int) -> np.ndarray:
    """(days, regions) window starts drawn day by day; returns each window's day mask and start rows."""
    starts = rng.random((days, len(f.REGIONS))) < probability
    mask = np.zeros_like(starts)
    for d, r in zip(*np.nonzero(starts), strict=True):
        mask[d : d + length, r] = True
    return starts, mask


def generate_demand(rng: np.random.Generator, days: int, start: dt.date) -> dict[str, np.ndarray]:
    """Daily orders (days, regions) with their promotion and shock flags."""
    mean = f.ORGYM_DEMAND_MEAN_UNITS * np.asarray(f.DEMAND_SCALE)
    _, promotion = _windows(rng, days, f.PROMOTION_PROBABILITY, f.PROMOTION_DAYS)
    shock_starts, shock = _windows(rng, days, f.SHOCK_PROBABILITY, f.SHOCK_DAYS)
    factor = np.ones((days, len(f.REGIONS)))
    for d, r in zip(*np.nonzero(shock_starts), strict=True):
        factor[d : d + f.SHOCK_DAYS, r] = f.SHOCK_FACTORS[int(rng.integers(len(f.SHOCK_FACTORS)))]
    rate = mean[None, :] * _season(days, start)[:, None] * np.where(promotion, f.PROMOTION_FACTOR, 1.0) * factor
    return {"orders": rng.poisson(rate).astype(np.float64), "promotion": promotion, "shock": shock}


def read_user_demand(path: Path | str) -> tuple[dt.date, np.ndarray]:
    """A user's demand file: its first date and the (days, regions) orders; a one-line error otherwise.

    Schema: ``date`` (YYYY-MM-DD, consecutive days, every region once per date), ``region`` (one of
    :data:`~.files.REGIONS`), ``orders_units`` (a finite number, 0 to 1e9).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as error:
        raise DatasetError(path, f"cannot be read as UTF-8 text ({error.__class__.__name__})") from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise DatasetError(path, "is empty (expected the header date,region,orders_units)")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in USER_DEMAND_COLUMNS if c not in header]
    if missing:
        raise DatasetError(path, f"missing column(s) {', '.join(missing)}", column=missing[0])
    at = {c: header.index(c) for c in USER_DEMAND_COLUMNS}
    cells: dict[dt.date, dict[str, float]] = {}
    for i, row in enumerate(rows[1:]):
        if len(row) < len(header):
            raise DatasetError(path, f"has {len(row)} fields, the header {len(header)}", row=i)
        raw_date, region, raw_orders = (row[at[c]].strip() for c in USER_DEMAND_COLUMNS)
        try:
            date = dt.date.fromisoformat(raw_date)
        except ValueError:
            raise DatasetError(path, f"'{raw_date}' is not a date YYYY-MM-DD", column="date", row=i) from None
        if region not in f.REGIONS:
            raise DatasetError(path, f"unknown region '{region}' (one of {', '.join(f.REGIONS)})", "region", i)
        try:
            orders = float(raw_orders)
        except ValueError:
            raise DatasetError(path, f"'{raw_orders}' is not a number", column="orders_units", row=i) from None
        if not (np.isfinite(orders) and 0.0 <= orders <= MAX_ORDERS_UNITS):
            raise DatasetError(path, f"{raw_orders} is outside 0..{MAX_ORDERS_UNITS:g}", column="orders_units", row=i)
        day = cells.setdefault(date, {})
        if region in day:
            raise DatasetError(path, f"region '{region}' is given twice for {date}", column="region", row=i)
        day[region] = orders
    if not cells:
        raise DatasetError(path, "has no data rows")
    dates = sorted(cells)
    for i, date in enumerate(dates):
        if date != dates[0] + dt.timedelta(days=i):
            raise DatasetError(path, f"dates jump from {dates[i - 1]} to {date} (days must be consecutive)", "date")
        absent = [r for r in f.REGIONS if r not in cells[date]]
        if absent:
            raise DatasetError(path, f"{date} has no row for region(s) {', '.join(absent)}", column="region")
    orders = np.array([[cells[d][r] for r in f.REGIONS] for d in dates])
    silent = [r for r, total in zip(f.REGIONS, orders.sum(axis=0), strict=True) if total <= 0.0]
    if silent:
        raise DatasetError(path, f"region(s) {', '.join(silent)} never order anything", column="orders_units")
    return dates[0], orders


def _multipliers(rng: np.random.Generator, scenario: FdiaScenario, n: int) -> list[float]:
    if scenario.severity is None:
        return [float(rng.choice(FDIA_MULTIPLIERS)) for _ in range(n)]
    return [float(rng.uniform(*scenario.severity)) for _ in range(n)]


def _clustered(rng: np.random.Generator, days: int, n_attacks: int, burst: int) -> tuple[np.ndarray, list[dict]]:
    # Records are region-major (row = region * days + day); a burst is `burst` consecutive days of one region.
    length = min(burst, days)
    taken = np.zeros(days * len(f.REGIONS), dtype=bool)
    chosen, bursts, count = [], [], 0
    while count < n_attacks:
        r = int(rng.integers(len(f.REGIONS)))
        first = int(rng.integers(0, days - length + 1))
        rows = r * days + np.arange(first, first + length)
        rows = rows[~taken[rows]][: n_attacks - count]
        if rows.size == 0:
            continue
        taken[rows] = True
        chosen.append(rows)
        count += rows.size
        bursts.append({"region": f.REGIONS[r], "first_day": int(rows[0] % days), "records": int(rows.size)})
    return (np.concatenate(chosen) if chosen else np.zeros(0, dtype=np.int64)), bursts


def inject_phantom_stock(
    rng: np.random.Generator, scenario: FdiaScenario, days: int, capacity_units: np.ndarray
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Spoofed report records: a (days, regions) flag, the reported level (units) and the manifest entry."""
    n_rows = days * len(f.REGIONS)
    n_attacks = int(np.round(scenario.rate * n_rows))
    bursts = None
    if scenario.pattern == "clustered":
        rows, bursts = _clustered(rng, days, n_attacks, scenario.burst_hours)
    else:  # uniform and stealthy draw alike: every record can be spoofed (a warehouse reports day and night)
        rows = rng.choice(np.arange(n_rows), size=n_attacks, replace=False)
    cap = 1.0 if scenario.pattern == "stealthy" else np.inf
    spoofed = np.zeros((len(f.REGIONS), days), dtype=bool)
    level = np.zeros((len(f.REGIONS), days))
    for row, m in zip(rows, _multipliers(rng, scenario, len(rows)), strict=True):
        r, d = divmod(int(row), days)
        spoofed[r, d] = True
        level[r, d] = round(float(capacity_units[r]) * min(m, cap), 2)
    entry = {**scenario.describe(), "injected_records": n_attacks}
    if bursts is not None:
        entry["burst_days"] = entry.pop("burst_hours")
        entry["bursts"] = bursts
    return spoofed.T.copy(), level.T.copy(), entry


def _csv(header: tuple[str, ...], rows: list[tuple]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return out.getvalue()


def _num(x: float) -> str:
    return repr(round(float(x), 6))


def build_supply_dataset(
    out_dir: Path | str,
    *,
    seed: int = f.DEFAULT_SEED,
    days: int = f.DEFAULT_DAYS,
    start: str = f.DEFAULT_START,
    fdia: FdiaScenario | None = None,
    demand_csv: Path | str | None = None,
) -> dict[str, Any]:
    """Write ``regions.csv``, ``demand.csv``, ``inventory_reports.csv`` and ``manifest.json`` into ``out_dir``.

    ``demand_csv`` (a user's demand, :func:`read_user_demand`) replaces the generated orders and
    sets the days and start. Returns the manifest. Raises :class:`~solarchain_eval.data.errors.DatasetError`
    (a bad demand file) or :class:`SupplyBuildError` (bad days or start) before writing anything; the
    attack scenario checks itself when it is made (:class:`~solarchain_eval.data.fdia.FdiaError`).
    """
    scenario = fdia or FdiaScenario()
    rng = np.random.default_rng(seed)
    if demand_csv is not None:
        first, orders = read_user_demand(demand_csv)
        days = len(orders)
        demand = {"orders": orders, "promotion": np.zeros_like(orders, bool), "shock": np.zeros_like(orders, bool)}
        mean = orders.mean(axis=0)
        source: dict[str, Any] = {"kind": "user", "file": str(demand_csv), "sha256": sha256_file(demand_csv)}
    else:
        if not 1 <= days <= MAX_DAYS:
            raise SupplyBuildError(f"days must be 1..{MAX_DAYS}, got {days}")
        try:
            first = dt.date.fromisoformat(start)
        except (TypeError, ValueError):
            raise SupplyBuildError(f"start '{start}' is not a date YYYY-MM-DD") from None
        demand = generate_demand(rng, days, first)
        mean = f.ORGYM_DEMAND_MEAN_UNITS * np.asarray(f.DEMAND_SCALE)
        source = {"kind": "generated", "model": "Poisson(20 x regional scale x season x promotion x shock)"}
    warehouse = np.round(mean * f.WAREHOUSE_CAPACITY_DAYS, 2)
    spoofed, level, attack = inject_phantom_stock(rng, scenario, days, warehouse)
    dates = [(first + dt.timedelta(days=d)).isoformat() for d in range(days)]
    texts = {
        f.REGIONS_FILE: _csv(
            f.REGION_COLUMNS,
            [
                (name, _num(mean[r]), _num(f.PRODUCTION_CAPACITY_UNITS[r]), _num(f.INITIAL_STOCK_UNITS[r]))
                + (f.LEAD_TIME_DAYS[r], _num(f.SPOILAGE_RATE_PER_DAY[r]), _num(warehouse[r]))
                + (_num(mean[r] * f.LANE_CAPACITY_DAYS),)
                for r, name in enumerate(f.REGIONS)
            ],
        ),
        f.DEMAND_FILE: _csv(
            ("day", "date", "region", "orders_units", "promotion", "shock"),
            [
                (d, dates[d], name, _num(demand["orders"][d, r]), int(demand["promotion"][d, r]))
                + (int(demand["shock"][d, r]),)
                for d in range(days)
                for r, name in enumerate(f.REGIONS)
            ],
        ),
        f.REPORTS_FILE: _csv(
            ("day", "region", "spoofed", "reported_level_units"),
            [(d, name, int(spoofed[d, r]), _num(level[d, r])) for d in range(days) for r, name in enumerate(f.REGIONS)],
        ),
    }
    out = Path(out_dir)
    for name, text in texts.items():
        atomic_write_text(out / name, text)
    manifest = {
        "task": "supply-chain",
        "seed": int(seed),
        "start": dates[0],
        "days": int(days),
        "regions": list(f.REGIONS),
        "demand": source,
        "fdia": attack,
        "parameters": {
            "orgym_demand_mean_units": f.ORGYM_DEMAND_MEAN_UNITS,
            "orgym_unit_price": f.ORGYM_UNIT_PRICE,
            "orgym_backlog_cost": f.ORGYM_BACKLOG_COST,
            "warehouse_capacity_days": f.WAREHOUSE_CAPACITY_DAYS,
            "lane_capacity_days": f.LANE_CAPACITY_DAYS,
            "weekday_factors": list(f.WEEKDAY_FACTORS),
            "annual_amplitude": f.ANNUAL_AMPLITUDE,
            "promotion": [f.PROMOTION_PROBABILITY, f.PROMOTION_DAYS, f.PROMOTION_FACTOR],
            "shock": [f.SHOCK_PROBABILITY, f.SHOCK_DAYS, list(f.SHOCK_FACTORS)],
        },
        "files": {name: sha256_file(out / name) for name in f.SUPPLY_FILES},
    }
    atomic_write_text(out / f.MANIFEST_FILE, json.dumps(manifest, indent=2) + "\n")
    return manifest
