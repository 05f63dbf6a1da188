"""False-data injection (FDIA) scenarios of a dataset build (docs/dataset.md#attack-scenarios).

A scenario is a rate (the fraction of generation records injected), a severity (how an injected
daylight reading relates to the node's physical maximum ``P_max``) and a pattern:

- ``uniform``: records drawn uniformly without replacement over the whole table (the paper's);
- ``clustered``: bursts of ``burst_hours`` consecutive hours in one city, every node of that
  city at once (a compromised city aggregator), until the rate is reached;
- ``stealthy``: daylight records only, each reported at ``min(m, 1) * P_max``: never above the
  physical maximum, so the physics check (``P_reported > P_max``) cannot see them and only the
  verification flag (``fdia_detected`` / ``verification_status``) marks them.

The default scenario (rate 0.05, the paper's multipliers, uniform) consumes the build's random
stream exactly as the paper's build did, so it reproduces the published files byte for byte.
Every injected record gets ``fdia_detected`` True and ``verification_status`` "rejected".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from ..common.errors import OptionsError

FDIA_FRACTION = 0.05
FDIA_MULTIPLIERS = (0.42, 1.38, 1.55, 1.82)
#: The attack patterns, each with its line of the ``--fdia-pattern`` help ("{burst_hours}": where
#: the burst length is set). The one list: the CLI's choices and the sweep YAML's derive from it.
FDIA_PATTERN_LINES: dict[str, str] = {
    "uniform": "records drawn uniformly (the paper's).",
    "clustered": "bursts of {burst_hours} consecutive hours in one city, all its nodes.",
    "stealthy": "daylight records reported at min(m, 1) x P_max, invisible to the physics check, marked only by "
    "the verification flag.",
}
FDIA_PATTERNS = tuple(FDIA_PATTERN_LINES)
DEFAULT_FDIA_PATTERN = "uniform"
#: A night or near-dark record (P_max_W at most this, W) injected by a non-stealthy attack
#: reports uniform(350, 1200) W, as in the paper's build.
DARK_P_MAX_W = 1.0
DEFAULT_BURST_HOURS = 6


class FdiaError(OptionsError, ValueError):
    """An attack scenario that is invalid or cannot be carried out on the table."""


@dataclass(frozen=True)
class FdiaScenario:
    """How false data is injected into the generation table.

    Parameters
    ----------
    rate : float
        Fraction of generation records injected, in [0, 1]; ``round(rate * rows)`` records.
    severity : (float, float) or None
        Multiplier range [lo, hi]: an injected daylight reading is ``P_max * m`` with
        ``m ~ uniform(lo, hi)``. None: the paper's multipliers {0.42, 1.38, 1.55, 1.82}.
    pattern : {"uniform", "clustered", "stealthy"}
    burst_hours : int
        Length of one clustered burst, hours.
    """

    rate: float = FDIA_FRACTION
    severity: tuple[float, float] | None = None
    pattern: str = DEFAULT_FDIA_PATTERN
    burst_hours: int = DEFAULT_BURST_HOURS

    def __post_init__(self) -> None:
        if not 0.0 <= float(self.rate) <= 1.0:
            raise FdiaError(f"fdia rate must be in [0, 1], got {self.rate}")
        if self.pattern not in FDIA_PATTERNS:
            raise FdiaError(f"unknown fdia pattern '{self.pattern}' (choose from {', '.join(FDIA_PATTERNS)})")
        if self.severity is not None:
            lo, hi = self.severity
            if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo <= hi):
                raise FdiaError(f"fdia severity must be LO:HI with 0 <= LO <= HI, got {lo}:{hi}")
        if self.burst_hours < 1:
            raise FdiaError(f"fdia burst hours must be at least 1, got {self.burst_hours}")

    def describe(self) -> dict[str, Any]:
        """The scenario as recorded in ``manifest.json``."""
        out: dict[str, Any] = {
            "rate": float(self.rate),
            "pattern": self.pattern,
            "severity": list(self.severity) if self.severity is not None else "paper multipliers",
            "multipliers": list(FDIA_MULTIPLIERS) if self.severity is None else None,
        }
        if self.pattern == "clustered":
            out["burst_hours"] = int(self.burst_hours)
        return out


def fdia_pattern_help(burst_hours: str = "burst_hours") -> str:
    """Every pattern as ``NAME: line``, in one paragraph; ``burst_hours`` names where the burst
    length is set (the CLI passes its option)."""
    return " ".join(f"{name}: {line.format(burst_hours=burst_hours)}" for name, line in FDIA_PATTERN_LINES.items())


def parse_severity(text: str) -> tuple[float, float]:
    """``"LO:HI"`` -> (lo, hi); a one-line error names the bad value."""
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise FdiaError(f"fdia severity '{text}' is not LO:HI (two numbers, e.g. 1.2:1.8)") from None
    FdiaScenario(severity=(lo, hi))  # range checks
    return lo, hi


def scenario_from_knobs(rate: float, severity: str | None, pattern: str, burst_hours: int) -> FdiaScenario:
    """The scenario the command line's and a sweep's knobs describe (``severity`` as ``"LO:HI"``,
    None: the paper's multipliers); a one-line error names a bad value."""
    return FdiaScenario(
        rate=rate,
        severity=parse_severity(severity) if severity is not None else None,
        pattern=pattern,
        burst_hours=burst_hours,
    )


def _multiplier(rng: np.random.Generator, scenario: FdiaScenario) -> float:
    if scenario.severity is None:
        return rng.choice(FDIA_MULTIPLIERS)
    return rng.uniform(*scenario.severity)


def _uniform_rows(rng: np.random.Generator, n_rows: int, n_attacks: int) -> np.ndarray:
    return rng.choice(np.arange(n_rows), size=n_attacks, replace=False)


def _stealthy_rows(rng: np.random.Generator, p_max: np.ndarray, n_attacks: int) -> np.ndarray:
    daylight = np.flatnonzero(p_max > DARK_P_MAX_W)
    if n_attacks > len(daylight):
        raise FdiaError(
            f"a stealthy attack on {n_attacks:,} records needs as many daylight records; the table has {len(daylight):,}"
        )
    return rng.choice(daylight, size=n_attacks, replace=False)


def _clustered_rows(
    rng: np.random.Generator, generation: pd.DataFrame, n_attacks: int, burst_hours: int
) -> tuple[np.ndarray, list[dict[str, Any]]]:
    # The table is node-major with the same hours for every node: row = node * H + hour.
    nodes = generation["node_id"].to_numpy()
    n_hours = int(np.flatnonzero(nodes != nodes[0])[0]) if (nodes != nodes[0]).any() else len(nodes)
    node_city = generation["city"].to_numpy()[::n_hours]
    cities = list(dict.fromkeys(node_city))
    city_nodes = [np.flatnonzero(node_city == c) for c in cities]
    length = min(burst_hours, n_hours)
    timestamps = generation["timestamp"].to_numpy()
    taken = np.zeros(len(generation), dtype=bool)
    chosen: list[np.ndarray] = []
    bursts: list[dict[str, Any]] = []
    count = 0
    while count < n_attacks:
        c = int(rng.integers(len(cities)))
        start = int(rng.integers(0, n_hours - length + 1))
        # Hour-major within the burst, so a truncated last burst is still contiguous in time.
        rows = (np.arange(start, start + length)[:, None] + city_nodes[c][None, :] * n_hours).ravel()
        rows = rows[~taken[rows]][: n_attacks - count]
        if rows.size == 0:
            continue
        taken[rows] = True
        chosen.append(rows)
        count += rows.size
        hours = np.unique(rows % n_hours)
        bursts.append(
            {
                "city": cities[c],
                "first_timestamp": str(timestamps[int(hours[0])]),
                "hours": int(hours.size),
                "records": int(rows.size),
            }
        )
    return (np.concatenate(chosen) if chosen else np.zeros(0, dtype=np.int64)), bursts


def inject_false_data(
    rng: np.random.Generator, generation: pd.DataFrame, scenario: FdiaScenario | None = None
) -> dict[str, Any]:
    """Inject false data into ``generation`` in place; returns the manifest's ``fdia`` entry.

    The rows are drawn first, then one value per row in draw order: a dark record
    (``P_max_W`` <= 1 W) of a non-stealthy attack reports round(uniform(350, 1200), 2) W; any
    other reports round(P_max_W * m, 2) W, with m capped at 1 for a stealthy attack.
    """
    scenario = scenario or FdiaScenario()
    n_rows = len(generation)
    n_attacks = int(np.round(scenario.rate * n_rows))
    p_max = generation["P_max_W"].to_numpy()
    bursts = None
    if scenario.pattern == "uniform":
        chosen = _uniform_rows(rng, n_rows, n_attacks)
    elif scenario.pattern == "stealthy":
        chosen = _stealthy_rows(rng, p_max, n_attacks)
    else:
        chosen, bursts = _clustered_rows(rng, generation, n_attacks, scenario.burst_hours)
    stealthy = scenario.pattern == "stealthy"
    reported = generation["P_reported_W"].to_numpy().copy()
    for row in chosen:
        if p_max[row] <= DARK_P_MAX_W and not stealthy:
            reported[row] = np.round(rng.uniform(350, 1200), 2)
        else:
            m = _multiplier(rng, scenario)
            reported[row] = np.round(p_max[row] * (min(m, 1.0) if stealthy else m), 2)
    generation["P_reported_W"] = reported
    fdia = np.zeros(n_rows, dtype=bool)
    fdia[chosen] = True
    generation["fdia_detected"] = fdia
    generation["verification_status"] = np.where(fdia, "rejected", "verified")
    entry = {**scenario.describe(), "injected_records": int(n_attacks)}
    if bursts is not None:
        entry["bursts"] = bursts
    return entry
