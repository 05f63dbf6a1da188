"""The supply-chain dataset: byte-reproducible builds, the attack scenarios, and one-line errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from solarchain_eval.common.atomic_files import sha256_file
from solarchain_eval.data.errors import DatasetError
from solarchain_eval.data.fdia import FdiaError, FdiaScenario
from solarchain_eval.supply import files as f
from solarchain_eval.supply.build import SupplyBuildError, build_supply_dataset
from solarchain_eval.supply.table import load_supply_table
from supply_fixtures import SUPPLY_DAYS, supply_dir, supply_table  # noqa: F401


def _bytes(root):
    return {name: (root / name).read_bytes() for name in (*f.SUPPLY_FILES, f.MANIFEST_FILE)}


def test_a_seed_gives_the_same_files_byte_for_byte_and_the_manifest_their_sha256s(tmp_path, supply_dir):  # noqa: F811
    again = tmp_path / "again"
    build_supply_dataset(again, seed=7, days=SUPPLY_DAYS, fdia=FdiaScenario(rate=0.2))
    assert _bytes(again) == _bytes(supply_dir)
    manifest = json.loads((supply_dir / f.MANIFEST_FILE).read_text())
    assert manifest["files"] == {name: sha256_file(supply_dir / name) for name in f.SUPPLY_FILES}
    other = tmp_path / "other"
    build_supply_dataset(other, seed=8, days=SUPPLY_DAYS, fdia=FdiaScenario(rate=0.2))
    assert (other / f.DEMAND_FILE).read_bytes() != (supply_dir / f.DEMAND_FILE).read_bytes()


def test_the_table_holds_the_published_parameters_and_the_attack(supply_table):  # noqa: F811
    t = supply_table
    assert t.regions == f.REGIONS and t.days == SUPPLY_DAYS and t.dates[0] == "2024-01-01"
    np.testing.assert_array_equal(t.lead_time_days, [3, 5, 8, 10, 12])
    np.testing.assert_array_equal(t.demand_mean_units, [24.0, 20.0, 16.0, 22.0, 18.0])
    np.testing.assert_array_equal(t.warehouse_capacity_units, 12.0 * t.demand_mean_units)
    assert int(t.spoofed.sum()) == round(0.2 * SUPPLY_DAYS * 5)
    assert not t.reported_level_units[~t.spoofed].any()
    ratio = t.reported_level_units[t.spoofed] / np.broadcast_to(t.warehouse_capacity_units, t.spoofed.shape)[t.spoofed]
    assert set(np.round(ratio, 2)) <= {0.42, 1.38, 1.55, 1.82}  # the paper's multipliers on the warehouse capacity
    # Orders follow the weekly season: Fridays (x1.15) busier than Sundays (x0.85) over twelve weeks.
    per_day = t.orders_units.sum(axis=1)
    assert per_day[4::7].mean() > per_day[6::7].mean()


def test_stealthy_reports_stay_within_capacity_and_clustered_ones_come_in_bursts(tmp_path):
    build_supply_dataset(tmp_path / "s", days=56, fdia=FdiaScenario(rate=0.3, pattern="stealthy"))
    stealthy = load_supply_table(tmp_path / "s")
    assert stealthy.spoofed.sum() == round(0.3 * 56 * 5)
    assert (stealthy.reported_level_units <= stealthy.warehouse_capacity_units[None, :]).all()
    assert not stealthy.capacity_check_rate.any()  # invisible to the capacity check
    build_supply_dataset(tmp_path / "u", days=56, fdia=FdiaScenario(rate=0.3))
    assert load_supply_table(tmp_path / "u").capacity_check_rate.any()
    manifest = build_supply_dataset(
        tmp_path / "c", days=56, fdia=FdiaScenario(rate=0.1, pattern="clustered", burst_hours=4)
    )
    clustered = load_supply_table(tmp_path / "c")
    for burst in manifest["fdia"]["bursts"]:
        r = f.REGIONS.index(burst["region"])
        days = slice(burst["first_day"], burst["first_day"] + burst["records"])
        assert clustered.spoofed[days, r].all()
    assert manifest["fdia"]["burst_days"] == 4 and clustered.spoofed.sum() == 28
    with pytest.raises(FdiaError, match="unknown fdia pattern 'bursty'"):
        build_supply_dataset(tmp_path / "x", fdia=FdiaScenario(pattern="bursty"))


def _demand_csv(path, rows):
    path.write_text("date,region,orders_units\n" + "".join(f"{d},{r},{o}\n" for d, r, o in rows))
    return path


def _good_rows(days=28):
    return [(f"2025-03-{d + 1:02d}", region, 10 + d) for d in range(days) for region in f.REGIONS]


def test_a_users_demand_replaces_the_generated_orders(tmp_path):
    source = _demand_csv(tmp_path / "demand.csv", _good_rows())
    manifest = build_supply_dataset(tmp_path / "out", demand_csv=source)
    table = load_supply_table(tmp_path / "out")
    assert table.days == 28 and table.dates[0] == "2025-03-01"
    np.testing.assert_array_equal(table.orders_units[:, 0], np.arange(10, 38))
    np.testing.assert_array_equal(table.demand_mean_units, np.full(5, 23.5))
    assert manifest["demand"] == {"kind": "user", "file": str(source), "sha256": sha256_file(source)}


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda rows: rows.__setitem__(7, ("2025-03-02", "east", "lots")),
            r"column 'orders_units', row 8 .*'lots' is not a number",
        ),
        (
            lambda rows: rows.__setitem__(3, ("2025-03-01", "mars", 1)),
            r"column 'region', row 4 .*unknown region 'mars'",
        ),
        (
            lambda rows: rows.__setitem__(12, ("2025-03-03", "north", -2)),
            r"column 'orders_units', row 13 .*-2 is outside",
        ),
        (lambda rows: rows.__setitem__(0, ("03/01/2025", "central", 1)), r"column 'date', row 1 .*not a date"),
        (lambda rows: rows.__setitem__(1, ("2025-03-01", "central", 1)), r"column 'region', row 2 .*given twice"),
        (lambda rows: rows.pop(9), r"column 'region'.*2025-03-02 has no row for region\(s\) west"),
    ],
)
def test_bad_user_demand_is_one_line_naming_file_column_and_row_and_writes_nothing(tmp_path, edit, message):
    rows = _good_rows()
    edit(rows)
    source = _demand_csv(tmp_path / "demand.csv", rows)
    out = tmp_path / "out"
    with pytest.raises(DatasetError, match=message) as caught:
        build_supply_dataset(out, demand_csv=source)
    assert str(caught.value).startswith(str(source)) and "\n" not in str(caught.value)
    assert not out.exists()


def test_a_damaged_dataset_file_is_named_with_its_column_and_row(tmp_path, supply_dir):  # noqa: F811
    damaged = tmp_path / "d"
    damaged.mkdir()
    for name in f.SUPPLY_FILES:
        (damaged / name).write_bytes((supply_dir / name).read_bytes())
    lines = (damaged / f.REPORTS_FILE).read_text().splitlines()
    lines[6] = lines[6].rsplit(",", 1)[0] + ",nan"
    (damaged / f.REPORTS_FILE).write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"inventory_reports.csv, column 'reported_level_units', row 6 \(line 7\)"):
        load_supply_table(damaged)
    (damaged / f.DEMAND_FILE).unlink()
    with pytest.raises(DatasetError, match=r"demand.csv: is missing"):
        load_supply_table(damaged)


@pytest.mark.parametrize(
    ("options", "message"),
    [({"days": 0}, r"days must be 1\.\.36600, got 0"), ({"start": "2024-13-01"}, r"start '2024-13-01' is not a date")],
)
def test_bad_build_options_are_one_line_and_write_nothing(tmp_path, options, message):
    with pytest.raises(SupplyBuildError, match=message):
        build_supply_dataset(tmp_path / "out", **options)
    assert not (tmp_path / "out").exists()
