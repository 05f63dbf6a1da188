"""Draw the two diagrams of docs/gallery.md with matplotlib: one market step, and the Planner/Auditor loop.

    python docs/hooks/diagrams.py      # writes docs/img/market_step.svg and docs/img/planner_auditor.svg

Boxes, arrows and text only; the formulas are those of docs/environment.md#rewards and
docs/planner_auditor.md. SVG metadata that would change between runs is left out.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
matplotlib.rcParams["svg.fonttype"] = "none"  # text stays text: smaller files, searchable labels
matplotlib.rcParams["svg.hashsalt"] = "solarchain-eval"  # the same ids every run: the same bytes
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "img"
MARKET = ("#fff3d6", "#c98a00")
AGENT = ("#e3f0ff", "#2f6db5")
DATA = ("#eef7ee", "#3a8a3a")
GOVERN = ("#f3e8ff", "#7a3fb5")


def _box(ax, x, y, w, h, lines, colours):
    fill, edge = colours
    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0,rounding_size=0.12", fc=fill, ec=edge, lw=1.4))
    top = y + h / 2 + (len(lines) - 1) * 0.17
    for i, line in enumerate(lines):
        ax.text(
            x + w / 2, top - i * 0.34, line, ha="center", va="center", fontsize=9, weight="bold" if i == 0 else None
        )


def _arrow(ax, start, end, label=None, label_at=None, connection="arc3"):
    ax.add_patch(
        FancyArrowPatch(
            start, end, arrowstyle="-|>", mutation_scale=12, lw=1.2, color="#444", connectionstyle=connection
        )
    )
    if label:
        lx, ly = label_at or ((start[0] + end[0]) / 2 + 0.1, (start[1] + end[1]) / 2)
        ax.text(lx, ly, label, fontsize=8, color="#333", ha="left", va="center")


def _canvas(width, height):
    figure, ax = plt.subplots(figsize=(width, height))
    ax.set_xlim(0, width)
    ax.set_ylim(0, height)
    ax.axis("off")
    figure.subplots_adjust(0, 0, 1, 1)
    return figure, ax


def market_step() -> plt.Figure:
    figure, ax = _canvas(9.0, 10.2)
    x, w = 1.2, 5.4
    rows = [
        (["Agent", "act(observation) → u ∈ [0, 1]³"], AGENT, 0.8),
        (["Decode and sanitise", "α = 0.05 + 0.60 u₁,  ℓ = 0.20 + 0.75 u₂,  b = 0.20 u₃", "α + ℓ ≤ 0.98"], MARKET, 1.1),
        (["1. Clearing demand", "Q_c = Q, or a 0.001 MWh floor in hours without trades"], MARKET, 0.8),
        (
            [
                "2. Physics gate",
                "invalid supply X, backing β = (α + ℓ) / 0.98",
                "A = β X unsafe backed,  V = A / (G_v + A)",
            ],
            MARKET,
            1.1,
        ),
        (
            [
                "3. Clearing",
                "Q̃ = Q_c · max(0.75, 1 − 0.8 b),  available = L + ℓ (G_v + A)",
                "matched M, unmet U, pool L, drawdown D",
            ],
            MARKET,
            1.1,
        ),
        (["4–6. Slippage, jitter, price, cities", "σ_exec, J = |a − a_prev|₁, token price p, fairness F"], MARKET, 0.8),
        (["7. Reward", "R = M − 1.5 D − 0.25 J − 0.4 U − 0.2 F − 2 (V + A)"], MARKET, 0.8),
        (["Next observation and info", "12 features; R, cost = V + A, matched energy, prices, …"], AGENT, 0.8),
    ]
    y, spans = 9.9, []
    for lines, colours, h in rows:
        y -= h
        _box(ax, x, y, w, h, lines, colours)
        spans.append((y, y + h))
        y -= 0.32
    for (bottom, _), (_, top) in zip(spans, spans[1:], strict=False):
        _arrow(ax, (x + w / 2, bottom), (x + w / 2, top))
    gate, clearing = spans[3], spans[4]
    _box(ax, 7.0, clearing[0], 1.85, gate[1] - clearing[0],
         ["The hour's data", "G_v verified", "G_r reported", "P_max bound", "Q trade demand"], DATA)  # fmt: skip
    _arrow(ax, (7.0, (gate[0] + gate[1]) / 2), (x + w, (gate[0] + gate[1]) / 2))
    _arrow(ax, (7.0, (clearing[0] + clearing[1]) / 2), (x + w, (clearing[0] + clearing[1]) / 2))
    last, first = spans[-1], spans[0]
    _arrow(ax, (x, (last[0] + last[1]) / 2), (x, (first[0] + first[1]) / 2), connection="bar,fraction=-0.12")
    ax.text(0.15, 5.0, "next hour", rotation=90, fontsize=8, color="#333", va="center")
    ax.text(x, 0.12, "Reward weights: the config's defaults; the no-physics ablation drops 2 (V + A).", fontsize=8)
    return figure


def planner_auditor() -> plt.Figure:
    figure, ax = _canvas(9.0, 6.6)
    _box(
        ax,
        0.3,
        5.1,
        3.6,
        1.2,
        ["Planner (once per episode)", "reads the episode's 24 hours ahead", "→ action bounds, audit policy"],
        GOVERN,
    )
    _box(
        ax,
        4.9,
        5.1,
        3.8,
        1.2,
        ["Policy (any agent)", "act(observation) → proposal a", "never sees the Planner or the data"],
        AGENT,
    )
    _box(ax, 4.9, 3.75, 3.8, 0.85, ["Clip to the Planner's bounds", "ā = bounded proposal (clips logged)"], MARKET)
    _box(
        ax,
        4.9,
        2.2,
        3.8,
        1.05,
        ["Scheduler", "hard: ν > τ_ν, gap < τ_Δ, σ > τ_σ", "soft: jitter > τ_κ; budget, cooldown"],
        MARKET,
    )
    _box(
        ax,
        4.9,
        0.6,
        3.8,
        1.05,
        ["Auditor (audited steps)", "approve: execute ā", "revise: execute its action (clipped)"],
        GOVERN,
    )
    _box(ax, 0.3, 0.6, 3.6, 1.05, ["Market step", "executed action → reward, info,", "next observation"], MARKET)
    _arrow(ax, (6.8, 5.1), (6.8, 4.6))
    _arrow(ax, (6.8, 3.75), (6.8, 3.25))
    _arrow(ax, (6.8, 2.2), (6.8, 1.65), "audit")
    _arrow(ax, (4.9, 2.7), (2.1, 1.65), "no audit: execute ā", label_at=(2.4, 2.45))
    _arrow(ax, (4.9, 1.1), (3.9, 1.1))
    _arrow(ax, (3.9, 5.45), (4.9, 4.2), "bounds", label_at=(3.95, 4.55))
    _arrow(ax, (2.9, 5.1), (4.9, 2.9), "audit policy", label_at=(2.55, 3.6))
    # the next hour: from the market step under the boxes and up the right side, back to the policy
    ax.plot([2.1, 2.1, 8.88, 8.88], [0.6, 0.38, 0.38, 5.7], color="#444", lw=1.2)
    _arrow(ax, (8.88, 5.7), (8.7, 5.7))
    ax.text(8.8, 3.0, "next hour", rotation=90, fontsize=8, color="#333", va="center", ha="center",
            bbox={"fc": "white", "ec": "none", "pad": 1})  # fmt: skip
    ax.text(
        0.3,
        0.1,
        "Every Planner and Auditor output is parsed against a strict schema and clipped to the ranges.",
        fontsize=8,
    )
    return figure


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    for name, draw in (("market_step", market_step), ("planner_auditor", planner_auditor)):
        figure = draw()
        figure.savefig(OUT / f"{name}.svg", metadata={"Date": None, "Creator": None})
        plt.close(figure)
        print(OUT / f"{name}.svg")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
