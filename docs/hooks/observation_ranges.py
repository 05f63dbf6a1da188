"""Print the typical observation ranges of docs/environment.md, measured on the default dataset.

Every observation the Static, Random and Myopic baselines receive over the paper's protocol
(run seeds 20260511-13 x 30 episodes x 24 steps each) is recorded, and each feature's minimum,
5th percentile, median, 95th percentile and maximum is printed as the page's Markdown table::

    python docs/hooks/observation_ranges.py          # print the table
    python docs/hooks/observation_ranges.py --data DIR

``tests/test_docs.py`` regenerates the table and fails when the page's differs from it.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

BASELINES = ("static", "random", "myopic")
QUANTILES = (0.05, 0.5, 0.95)


class _Recording:
    """A baseline that keeps every observation it is given (and otherwise is the baseline)."""

    def __init__(self, inner: Any, name: str, seen: list[np.ndarray]) -> None:
        self.inner, self.name, self.seen = inner, name, seen

    def begin_run(self, run_seed: int) -> None:
        hook = getattr(self.inner, "begin_run", None)
        if hook is not None:
            hook(run_seed)

    def act(self, observation: np.ndarray) -> np.ndarray:
        self.seen.append(np.array(observation, dtype=np.float32))
        return self.inner.act(observation)


def observations(data: Path | None = None) -> np.ndarray:
    """Every observation of the three baselines over the paper's protocol, one row per step."""
    import solarchain_eval
    from solarchain_eval.config import BenchmarkConfig
    from solarchain_eval.market.baselines import make_baseline

    market = BenchmarkConfig().market
    seen: list[np.ndarray] = []
    agents = [_Recording(make_baseline(name, market), f"{name}-recorded", seen) for name in BASELINES]
    solarchain_eval.evaluate(agents, data=data)
    return np.stack(seen)


def ranges_table(data: Path | None = None) -> str:
    """The Markdown table: one row per observation feature."""
    from solarchain_eval.market.observation import OBSERVATION_NAMES

    seen = observations(data)
    lines = ["| # | name | min | 5 % | median | 95 % | max |", "|--:|---|--:|--:|--:|--:|--:|"]
    for index, name in enumerate(OBSERVATION_NAMES):
        column = seen[:, index].astype(np.float64)
        values = [column.min(), *np.quantile(column, QUANTILES), column.max()]
        # 4 decimals first, so a float's 6e-17 prints as 0 (and -0.0 as 0)
        lines.append(f"| {index} | `{name}` | " + " | ".join(f"{round(float(v), 4) + 0.0:.3g}" for v in values) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Print the observation ranges table of docs/environment.md.")
    parser.add_argument("--data", type=Path, default=None, help="dataset directory (default: the embedded default)")
    args = parser.parse_args(argv)
    print(ranges_table(args.data), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
