"""The leaderboard's Pareto figure labels every point without one label over another."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg

from solarchain_eval.report.figure_style import new_figure
from solarchain_eval.report.leaderboard.pareto import pareto_figure, pareto_front, place_labels


def test_labels_of_close_points_do_not_overlap():
    # a user's agent a hair from Static, and three more points spread out
    x = np.array([0.1800, 0.1801, 0.101, 0.107, 0.130])
    y = np.array([-21.650, -21.655, -21.39, -23.28, -21.67])
    labels = ["my_agent", "static", "myopic", "random", "Cautious"]
    with new_figure() as (figure, axes):
        ax = axes[0, 0]
        ax.scatter(x, y)
        ax.margins(x=0.15, y=0.1)
        FigureCanvasAgg(figure)
        figure.draw_without_rendering()
        figure.set_layout_engine("none")
        notes = place_labels(ax, x, y, labels, first=pareto_front(x, y))
        renderer = figure.canvas.get_renderer()
        boxes = {note.get_text(): note.get_window_extent(renderer) for note in notes}
    assert sorted(boxes) == sorted(labels)
    overlapping = [(a, b) for a, b in itertools.combinations(boxes, 2) if boxes[a].overlaps(boxes[b])]
    assert overlapping == []
    assert all(ax.bbox.contains(b.x0, b.y0) and ax.bbox.contains(b.x1, b.y1) for b in boxes.values())


def test_pareto_figure_still_draws_nan_and_single_points():
    points = pd.DataFrame(
        {
            "setting": ["main", "main", "no_physics"],
            "policy": ["static", "mine", "static"],
            "artificial_liquidity_MWh_mean": [0.18, np.nan, 0.2],
            "cumulative_reward_mean": [-21.6, -21.7, -20.0],
            "cumulative_reward_low": [-22.0, np.nan, np.nan],
            "cumulative_reward_high": [-21.2, np.nan, np.nan],
        }
    )
    figure = pareto_figure(points)
    assert figure["png"].startswith(b"\x89PNG") and b"<svg" in figure["svg"]
