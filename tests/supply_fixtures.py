"""A small supply-chain dataset shared by the supply tests (12 weeks, a heavier attack than the default)."""

from __future__ import annotations

from pathlib import Path

import pytest

from solarchain_eval.data.fdia import FdiaScenario
from solarchain_eval.supply.build import build_supply_dataset
from solarchain_eval.supply.table import SupplyTable, load_supply_table

SUPPLY_SEED = 7
SUPPLY_DAYS = 84


@pytest.fixture(scope="session")
def supply_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("supply-data")
    build_supply_dataset(out, seed=SUPPLY_SEED, days=SUPPLY_DAYS, fdia=FdiaScenario(rate=0.2))
    return out


@pytest.fixture(scope="session")
def supply_table(supply_dir: Path) -> SupplyTable:
    return load_supply_table(supply_dir)
