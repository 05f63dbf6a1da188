"""Figure style, colours and deterministic saving (PNG and SVG).

Figures are built on :class:`matplotlib.figure.Figure` directly (no pyplot global state, Agg
rendering), inside :func:`matplotlib.rc_context` with a fixed SVG hash salt; PNG and SVG carry
no date or software metadata, so the same inputs give byte-identical files.
"""

from __future__ import annotations

import io
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..common.atomic_files import atomic_write_bytes
from .naming import SETTINGS

#: One colour per policy, the same in every figure (Okabe-Ito-like, colour-blind safe).
POLICY_COLOURS = {
    "static": "#7f7f7f",
    "random": "#b8a000",
    "myopic": "#8c564b",
    "ppo": "#0072b2",
    "sac": "#e69f00",
    "dqn": "#009e73",
}
#: Colours for policies the paper does not have, handed out by sorted name.
EXTRA_COLOURS = ("#cc79a7", "#d55e00", "#56b4e9", "#9467bd", "#17becf", "#bcbd22")
#: One colour per setting (four-setting figures).
SETTING_COLOURS = dict(zip(SETTINGS, ("#0072b2", "#d55e00", "#009e73", "#cc79a7"), strict=True))

STYLE = {
    "svg.hashsalt": "solarchain-eval-report",
    "svg.fonttype": "path",
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.grid": True,
    "grid.alpha": 0.25,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "legend.fontsize": 8,
    "legend.frameon": False,
    "figure.dpi": 100,
}
PNG_DPI = 150
FIGSIZE = (5.2, 3.6)


def policy_colour(policy: str, known: Sequence[str] = ()) -> str:
    """The colour of ``policy``; policies outside the paper get a stable colour by sorted name."""
    if policy in POLICY_COLOURS:
        return POLICY_COLOURS[policy]
    others = sorted({p for p in (*known, policy) if p not in POLICY_COLOURS})
    return EXTRA_COLOURS[others.index(policy) % len(EXTRA_COLOURS)]


@dataclass(frozen=True)
class FigureFile:
    """A written figure: key, title, caption and its PNG and SVG paths."""

    key: str
    title: str
    caption: str
    png: Path
    svg: Path


@contextmanager
def new_figure(
    nrows: int = 1, ncols: int = 1, figsize: tuple[float, float] = FIGSIZE, **kwargs
) -> Iterator[tuple[Figure, np.ndarray]]:
    """A figure and its axes (always a 2-D array) under the report style."""
    with matplotlib.rc_context(STYLE):
        figure = Figure(figsize=figsize, layout="constrained")
        axes = figure.subplots(nrows, ncols, squeeze=False, **kwargs)
        yield figure, axes


def figure_bytes(figure: Figure) -> dict[str, bytes]:
    """The figure as PNG and SVG bytes (``{"png": ..., "svg": ...}``), without metadata that would vary."""
    rendered = {}
    with matplotlib.rc_context(STYLE):
        for fmt, metadata in (("png", {"Software": None}), ("svg", {"Date": None, "Creator": None})):
            buffer = io.BytesIO()
            figure.savefig(buffer, format=fmt, dpi=PNG_DPI, metadata=metadata)
            rendered[fmt] = buffer.getvalue()
    return rendered


def save_figure(figure: Figure, out_dir: Path, key: str, title: str, caption: str) -> FigureFile:
    """Write ``<key>.png`` and ``<key>.svg`` atomically, without metadata that would vary."""
    paths = {
        fmt: atomic_write_bytes(Path(out_dir) / f"{key}.{fmt}", data) for fmt, data in figure_bytes(figure).items()
    }
    return FigureFile(key=key, title=title, caption=caption, png=paths["png"], svg=paths["svg"])


def jitter(rng: np.random.Generator, n: int, width: float = 0.12) -> np.ndarray:
    """Horizontal offsets for plotting ``n`` points over a category (seeded)."""
    return rng.uniform(-width, width, size=n)


def points_with_mean(
    ax: Axes, position: float, values: np.ndarray, colour: str, rng: np.random.Generator, *, width: float = 0.12
) -> None:
    """Translucent points (one per rollout) and a bold mean bar at ``position``."""
    ax.scatter(position + jitter(rng, values.size, width), values, s=9, color=colour, alpha=0.35, linewidths=0)
    ax.hlines(float(np.mean(values)), position - 1.8 * width, position + 1.8 * width, color=colour, linewidth=2.2)


def label_categories(ax: Axes, labels: Sequence[str]) -> None:
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(labels)
    ax.set_xlim(-0.6, len(labels) - 0.4)
