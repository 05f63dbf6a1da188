"""Checksums of the paper's published dataset (from the release's SHA256SUMS).

Used to tell a user when a build reproduced the published files byte for byte.
"""

from __future__ import annotations

#: sha256 of the cached Open-Meteo payload the paper's dataset was built from.
PAPER_WEATHER_SHA256 = "9c373f057ade383f2adf21941c1bbefc13bce38f9aa7641874052e9fec510842"

#: sha256 of the four CSVs published with the paper (seed 20260511, April 2026).
PAPER_DATASET_SHA256 = {
    "market_liquidity.csv": "ddf7b4b8c34b11a898ed5a32661fce5777f1d17d0a49f1da29b85347e53cbced",
    "p2p_trades.csv": "4bcd0cff533f99e3787f70d87ecc5e0a268c668cd47120c7936f87ab3c2c91ee",
    "spatiotemporal_generation.csv": "caa0d95656e618e7d54c98bfed507128a94edac454b8b964ac06f3541f9b190e",
    "urban_energy_nodes.csv": "6ccea1564cb709df7b8e4bb784e72afc5ef0f0014d7ff96f55ba1701f6d5bcd0",
}


def matches_published(file_hashes: dict[str, str]) -> bool:
    return all(file_hashes.get(name) == digest for name, digest in PAPER_DATASET_SHA256.items())
