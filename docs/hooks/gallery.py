"""Make the figures of docs/gallery.md with the package's own commands, and copy them into docs/img/gallery/.

    python docs/hooks/gallery.py [--work DIR]

Runs, in a scratch folder (or DIR), exactly the commands the gallery page lists:

    solarchain-eval evaluate --policies static,random,myopic,examples/my_agent.py:Cautious --episodes 2 --out run
    solarchain-eval report run --formats md
    solarchain-eval leaderboard run --out board --formats md

then copies four of the PNGs they write. The diagrams are drawn by docs/hooks/diagrams.py.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
GALLERY = ROOT / "docs" / "img" / "gallery"
COMMANDS = (
    ["evaluate", "--policies", "static,random,myopic,examples/my_agent.py:Cautious", "--episodes", "2", "--out", "run"],
    ["report", "run", "--formats", "md"],
    ["leaderboard", "run", "--out", "board", "--formats", "md"],
)
#: Gallery file name <- the file a command wrote.
FIGURES = {
    "reward_distribution.png": "run/report/figures/reward_distribution.png",
    "utility_safety_frontier.png": "run/report/figures/utility_safety_frontier.png",
    "city_hour_reward.png": "run/report/figures/city_hour_reward.png",
    "leaderboard_pareto.png": "board/pareto.png",
}


def make(work: Path) -> list[Path]:
    from solarchain_eval.cli import app

    work.mkdir(parents=True, exist_ok=True)
    examples = work / "examples"
    if not examples.exists():
        examples.symlink_to(ROOT / "examples")
    here = Path.cwd()
    os.chdir(work)
    try:
        for command in COMMANDS:
            print("solarchain-eval", " ".join(command), flush=True)
            app(command, standalone_mode=False)
    finally:
        os.chdir(here)
    GALLERY.mkdir(parents=True, exist_ok=True)
    return [Path(shutil.copyfile(work / source, GALLERY / name)) for name, source in FIGURES.items()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Make the gallery's figures with the package's commands.")
    parser.add_argument("--work", type=Path, default=None, help="folder for the run and the board (default: temporary)")
    args = parser.parse_args(argv)
    if args.work is not None:
        written = make(args.work)
    else:
        with tempfile.TemporaryDirectory() as scratch:
            written = make(Path(scratch))
    for path in written:
        print(f"{path.relative_to(ROOT)}  {path.stat().st_size:,} bytes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
