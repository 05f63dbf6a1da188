"""File names, regions and the published parameters of the supply-chain dataset (docs/tasks/supply_chain.md).

The network's numbers come from OR-Gym's network inventory problem (Hubbs et al., 2020,
``NetInvMgmtMasterEnv``: retail demand Poisson(20) per period, production capacities 80-90 units,
initial stocks 80-110 units at the distribution nodes, lead times 3-12 periods, retail price 2.0,
backlog cost 0.1) and from the exponential-decay inventory model of Ghare and Schrader (1963) for
spoilage. Where neither gives a number (regional demand scale, warehouse and lane capacities,
spoilage rates), the value is this benchmark's choice, marked as such in the dataset card.
"""

from __future__ import annotations

REGIONS_FILE = "regions.csv"
DEMAND_FILE = "demand.csv"
REPORTS_FILE = "inventory_reports.csv"
MANIFEST_FILE = "manifest.json"
SUPPLY_FILES = (REGIONS_FILE, DEMAND_FILE, REPORTS_FILE)
#: ``regions.csv``'s columns, in order (the builder writes them, the loader requires them).
REGION_COLUMNS = (
    "region",
    "demand_mean_units",
    "production_capacity_units",
    "initial_stock_units",
    "lead_time_days",
    "spoilage_rate_per_day",
    "warehouse_capacity_units",
    "lane_capacity_units",
)

#: The regions, each one warehouse fed by one supplier (alphabetical: the order of every array).
REGIONS = ("central", "east", "north", "south", "west")

#: OR-Gym's retail demand: Poisson with mean 20 units per period (one period = one day here).
ORGYM_DEMAND_MEAN_UNITS = 20.0
#: Regional scale of that mean (this benchmark's choice: regions of unequal size).
DEMAND_SCALE = (1.2, 1.0, 0.8, 1.1, 0.9)
#: OR-Gym's manufacturer capacities (90, 90, 80 units per period), cycled over the regions.
PRODUCTION_CAPACITY_UNITS = (90.0, 90.0, 80.0, 90.0, 80.0)
#: OR-Gym's initial inventories of its retailer and distributors (100, 110, 80 units), cycled.
INITIAL_STOCK_UNITS = (100.0, 110.0, 80.0, 100.0, 110.0)
#: Lead times drawn from OR-Gym's edges (3, 5, 8, 10, 12 of its 3-12 periods), days.
LEAD_TIME_DAYS = (3, 5, 8, 10, 12)
#: Daily decay rate θ of Ghare and Schrader's model dI/dt = -θ I (values this benchmark's choice).
SPOILAGE_RATE_PER_DAY = (0.010, 0.005, 0.020, 0.010, 0.015)
#: Warehouse capacity in days of the region's mean demand (this benchmark's choice): the physical
#: maximum a stock report can honestly show, as P_max is for a PV node.
WAREHOUSE_CAPACITY_DAYS = 12.0
#: Outbound lane capacity in days of the region's mean demand per day (this benchmark's choice).
LANE_CAPACITY_DAYS = 2.0
#: OR-Gym's retail price and backlog cost per unit (recorded in the manifest; the revenue metric
#: uses the price).
ORGYM_UNIT_PRICE = 2.0
ORGYM_BACKLOG_COST = 0.1

# Demand shape (this benchmark's choices, recorded in the manifest).
WEEKDAY_FACTORS = (1.10, 1.05, 1.00, 1.00, 1.15, 0.85, 0.85)  # Monday first
ANNUAL_AMPLITUDE = 0.15  # seasonal swing, peak in mid-December
PROMOTION_PROBABILITY = 0.03  # a region starts a promotion on a given day
PROMOTION_DAYS, PROMOTION_FACTOR = 3, 1.5
SHOCK_PROBABILITY = 0.01  # a regional demand shock starts on a given day
SHOCK_DAYS, SHOCK_FACTORS = 5, (0.4, 1.8)

DEFAULT_SEED = 20260511
DEFAULT_START = "2024-01-01"  # a Monday
DEFAULT_DAYS = 364
