"""Named splits: train (the paper's April 2026), test (the held-out months), the paper's month by start day."""

from __future__ import annotations

import pytest

from solarchain_eval.data.splits import PAPER_DATASET, SPLITS, dataset_dir, get_split


def test_the_five_splits_and_their_datasets():
    assert list(SPLITS) == ["train", "test", "paper-early", "paper-late", "paper-cities"]
    assert get_split("train").datasets == (PAPER_DATASET,)
    assert get_split("test").datasets == tuple(f"tmy-3sites-{m:02d}" for m in range(1, 13))
    assert {s.name: s.role for s in SPLITS.values()} == {
        "train": "train",
        "test": "test",
        "paper-early": "train",
        "paper-late": "test",
        "paper-cities": "test",
    }
    assert get_split("paper-cities").datasets == tuple(f"paper-cities-2026-{m:02d}" for m in range(5, 11))
    with pytest.raises(KeyError, match="unknown split 'dev'.*train, test, paper-early, paper-late, paper-cities"):
        get_split("dev")


def test_train_and_test_share_no_dataset():
    assert not set(get_split("train").datasets) & set(get_split("test").datasets)


def test_the_paper_month_splits_at_day_21_and_covers_every_start_day():
    from solarchain_eval.envs.env import start_hours

    (early,) = get_split("paper-early").entries
    (late,) = get_split("paper-late").entries
    assert early.start_days == tuple(range(1, 22)) and late.start_days == tuple(range(22, 31))
    assert late.start_hours()[:2] == (504, 528)
    # Together they are every start hour the environment draws from the paper's 720 hours, once each.
    assert sorted(early.start_hours() + late.start_hours()) == list(start_hours(720, 24))
    assert get_split("train").entries[0].start_hours() is None


def test_split_datasets_resolve_to_directories(tmp_path, monkeypatch):
    from solarchain_eval.data.default import default_dataset_dir

    monkeypatch.setenv("SOLARCHAIN_CACHE_DIR", str(tmp_path))
    assert dataset_dir(PAPER_DATASET, build=False) == default_dataset_dir(build=False)
    assert dataset_dir("tmy-3sites-07", build=False) == tmp_path / "datasets" / "tmy-3sites-07"
    assert dataset_dir("paper-cities-2026-09", build=False) == tmp_path / "datasets" / "paper-cities-2026-09"
    with pytest.raises(KeyError, match="unknown dataset 'paper'"):
        dataset_dir("paper", build=False)


def test_the_cli_lists_the_splits_and_the_rule():
    from typer.testing import CliRunner

    from solarchain_eval.cli import app

    result = CliRunner().invoke(app, ["data", "splits"], terminal_width=200)
    assert result.exit_code == 0, result.output
    rows = {line.split("│")[1].strip(): line for line in result.output.splitlines() if line.count("│") >= 5}
    assert "22-30" in rows["paper-late"] and "1-21" in rows["paper-early"]
    assert "tmy-3sites-01 ... tmy-3sites-12 (12)" in rows["test"]
    assert "paper-cities-2026-05 ..." in rows["paper-cities"] and "paper-cities-2026-10 (6)" in result.output
    assert "rule: train and tune on the train split only; report the test split" in result.output
