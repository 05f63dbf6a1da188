"""The generalisation study of docs/generalisation.md: trained agents over the held-out suite.

Reads suite roots laid out as ``ROOT/<backend>/<suite>/<group>/<run seed>/`` (each one
``solarchain-eval evaluate --suite SUITE --seeds SEED ...`` run, see the page for the commands),
where ``group`` is ``main``, ``no_physics`` or ``llm``, and writes to ``OUT``:

- ``lead.csv``: per backend, suite and policy, the IQM of the normalised score (0 = Random,
  1 = Myopic on each entry) pooled over the run seeds, with its stratified-bootstrap interval,
  and P(policy > Myopic) (the package's rliable functions, ``solarchain_eval.evaluation.suite_stats``);
- ``contrasts.csv``: per backend, suite, learned policy and metric, the paired difference
  no_physics − main and llm − main (same entries, seeds and episodes), with a bootstrap interval
  that resamples episodes within each entry;
- ``heatmap.png``: each learned policy's mean normalised score per entry;
- ``profiles.png``: per backend, the performance profile of every policy over the held-out suite
  (the fraction of its episodes, all entries and seeds, with a normalised score above τ).

Usage: ``python examples/generalisation_study.py ROOT OUT``
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from solarchain_eval.evaluation.suite_stats import (  # noqa: E402
    aggregate_iqm,
    draw_performance_profile,
    probability_of_improvement,
    stratified_bootstrap_interval,
)

LEARNED = ("ppo", "sac", "dqn")
METRICS = ("cumulative_reward", "physics_violation_rate", "artificial_liquidity_MWh", "episode_volume")
EPISODE = ["entry", "run_seed", "episode"]
REPS, SEED = 2000, 0


def read_group(root: Path, backend: str, suite: str, group: str) -> pd.DataFrame:
    """Every episode of one group: raw score and the metrics, one row per (entry, policy, seed, episode)."""
    frames = []
    for seed_dir in sorted((root / backend / suite / group).iterdir()):
        for run in sorted(p for p in seed_dir.iterdir() if (p / "metrics.csv").is_file()):
            metrics = pd.read_csv(run / "metrics.csv")
            metrics.insert(0, "entry", run.name)
            frames.append(metrics)
    return pd.concat(frames, ignore_index=True)


def normalised(frame: pd.DataFrame) -> pd.DataFrame:
    """Each episode's cumulative reward on each entry's Random (0) to Myopic (1) scale, the
    references pooled over the run seeds (what one multi-seed ``evaluate --suite`` run does)."""
    refs = frame[frame["policy"].isin(["random", "myopic"])].groupby(["entry", "policy"])["cumulative_reward"].mean()
    low = frame["entry"].map(refs.xs("random", level="policy"))
    high = frame["entry"].map(refs.xs("myopic", level="policy"))
    return frame.assign(normalised=(frame["cumulative_reward"] - low) / (high - low))


def learned(frame: pd.DataFrame) -> tuple[str, ...]:
    """The learned policies a backend's runs hold (a training may leave one out, e.g. SB3's SAC)."""
    return tuple(p for p in LEARNED if p in set(frame["policy"]))


def matrix(frame: pd.DataFrame, policy: str) -> np.ndarray:
    """The (episodes, entries) score matrix of one policy."""
    rows = frame[frame["policy"] == policy].pivot_table(
        index=["run_seed", "episode"], columns="entry", values="normalised"
    )
    return rows.to_numpy()


def lead_rows(frame: pd.DataFrame, backend: str, suite: str) -> list[dict]:
    myopic = matrix(frame, "myopic")
    rows = []
    for policy in (*learned(frame), "static", "myopic", "random"):
        scores = matrix(frame, policy)
        low, high = stratified_bootstrap_interval(scores, aggregate_iqm, reps=REPS, seed=SEED)
        rows.append(
            {
                "backend": backend,
                "suite": suite,
                "policy": policy,
                "entries": scores.shape[1],
                "iqm": aggregate_iqm(scores),
                "iqm_low": low,
                "iqm_high": high,
                "p_over_myopic": probability_of_improvement(scores, myopic) if policy != "myopic" else np.nan,
            }
        )
    return rows


def paired_difference(treated: pd.DataFrame, base: pd.DataFrame, metric: str) -> tuple[float, float, float]:
    """Mean of treated − base over paired episodes, and a 95 % interval resampling episodes within entries."""
    merged = treated.merge(base, on=EPISODE, suffixes=("_t", "_b"), validate="one_to_one")
    delta = (merged[f"{metric}_t"] - merged[f"{metric}_b"]).to_numpy()
    groups = [np.flatnonzero(merged["entry"].to_numpy() == e) for e in merged["entry"].unique()]
    rng = np.random.default_rng(SEED)
    draws = np.empty(REPS)
    for r in range(REPS):
        draws[r] = np.concatenate([delta[rng.choice(g, g.size)] for g in groups]).mean()
    return float(delta.mean()), float(np.percentile(draws, 2.5)), float(np.percentile(draws, 97.5))


def contrast_rows(groups: dict[str, pd.DataFrame], backend: str, suite: str) -> list[dict]:
    rows = []
    for treated, base in (("no_physics", "main"), ("llm", "main")):
        for policy in learned(groups[base]):
            t = groups[treated][groups[treated]["policy"] == policy]
            b = groups[base][groups[base]["policy"] == policy]
            for metric in METRICS:
                mean, low, high = paired_difference(t, b, metric)
                rows.append(
                    {
                        "backend": backend,
                        "suite": suite,
                        "contrast": f"{treated} - {base}",
                        "policy": policy,
                        "metric": metric,
                        "base": float(b[metric].mean()),
                        "treated": float(t[metric].mean()),
                        "delta": mean,
                        "delta_low": low,
                        "delta_high": high,
                    }
                )
    return rows


def heatmap(frames: dict[str, pd.DataFrame], path: Path) -> None:
    labels, cells, entries = [], [], None
    for backend, frame in frames.items():
        means = frame.groupby(["policy", "entry"])["normalised"].mean().unstack()
        entries = list(means.columns)
        for policy in learned(frame):
            labels.append(f"{policy} ({backend})")
            cells.append(means.loc[policy].to_numpy())
    data = np.vstack(cells)
    figure, axes = plt.subplots(figsize=(1.0 + 0.75 * len(entries), 0.5 + 0.45 * len(labels)))
    limit = float(np.nanmax(np.abs(data - 1.0)))
    image = axes.imshow(data, cmap="RdBu", vmin=1.0 - limit, vmax=1.0 + limit, aspect="auto")
    axes.set_xticks(range(len(entries)), [e.removeprefix("tmy-3sites-") for e in entries])
    axes.set_yticks(range(len(labels)), labels)
    axes.set_xlabel("held-out entry (tmy-3sites month)")
    for (i, j), value in np.ndenumerate(data):
        axes.text(j, i, f"{value:.2f}", ha="center", va="center", fontsize=7)
    figure.colorbar(image, ax=axes, label="mean normalised score\n(0 = Random, 1 = Myopic)")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def profiles(frames: dict[str, pd.DataFrame], path: Path) -> None:
    """One panel per backend: every policy's performance profile over the held-out entries."""
    columns = min(2, len(frames))
    rows = -(-len(frames) // columns)
    figure, panels = plt.subplots(rows, columns, figsize=(5.5 * columns, 4.0 * rows), sharey=True, squeeze=False)
    colours = dict(zip((*LEARNED, "myopic", "static", "random"), plt.get_cmap("tab10").colors, strict=False))
    for axes in panels.ravel()[len(frames) :]:
        axes.set_visible(False)
    for axes, (backend, frame) in zip(panels.ravel(), frames.items(), strict=False):
        shown = (*learned(frame), "myopic", "static", "random")
        draw_performance_profile(axes, {p: matrix(frame, p) for p in shown}, colours)
        axes.set_title(f"held-out suite, {backend}")
        axes.set_xlim(-1.0, 3.0)  # the bulk of every profile; the tails run to the scores' extremes
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(root: Path, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    lead, contrasts, held_out = [], [], {}
    for backend in sorted(p.name for p in root.iterdir() if p.is_dir()):
        for suite in ("train", "heldout"):
            groups = {g: read_group(root, backend, suite, g) for g in ("main", "no_physics", "llm")}
            main_frame = normalised(groups["main"])
            lead += lead_rows(main_frame, backend, suite)
            contrasts += contrast_rows(groups, backend, suite)
            if suite == "heldout":
                held_out[backend] = main_frame
    pd.DataFrame(lead).to_csv(out / "lead.csv", index=False)
    pd.DataFrame(contrasts).to_csv(out / "contrasts.csv", index=False)
    heatmap(held_out, out / "heatmap.png")
    profiles(held_out, out / "profiles.png")
    print(f"wrote {out / 'lead.csv'}, {out / 'contrasts.csv'}, {out / 'heatmap.png'}, {out / 'profiles.png'}")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
