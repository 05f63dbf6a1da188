"""File names of a dataset directory (kept apart so loading never imports the build's pvlib)."""

NODES_FILE = "urban_energy_nodes.csv"
GENERATION_FILE = "spatiotemporal_generation.csv"
MARKET_FILE = "market_liquidity.csv"
TRADES_FILE = "p2p_trades.csv"
MANIFEST_FILE = "manifest.json"
DATASET_FILES = (NODES_FILE, GENERATION_FILE, MARKET_FILE, TRADES_FILE)
