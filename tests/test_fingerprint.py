"""The protocol fingerprint: what it hashes, what it leaves out, and how a grid's units merge."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import solarchain_eval
from solarchain_eval.config import BenchmarkConfig
from solarchain_eval.evaluation.fingerprint import (
    merge_fingerprints,
    protocol_difference,
    protocol_fingerprint,
    protocol_id,
)
from solarchain_eval.protocol import EPISODE_SEED_RULES, episode_seed_rule_name, independent_episode_seeds

BASE = {
    "dataset_sha256": {"a.csv": "1" * 64, "b.csv": "2" * 64},
    "run_seeds": [20260511, 20260512, 20260513],
    "episodes": 30,
    "episode_seed_rule": "paper",
    "setting": "main",
    "action_modes": {"static": "continuous"},
}


def fingerprint(config: BenchmarkConfig | None = None, **changes) -> dict:
    return protocol_fingerprint(**{**BASE, **changes}, config=config or BenchmarkConfig())


def test_every_task_field_changes_the_id() -> None:
    reference = protocol_id(fingerprint())
    variants = {
        "dataset_sha256": fingerprint(dataset_sha256={"a.csv": "1" * 64, "b.csv": "3" * 64}),
        "run_seeds": fingerprint(run_seeds=[1, 2, 3]),
        "episodes": fingerprint(episodes=29),
        "episode_seed_rule": fingerprint(episode_seed_rule="independent"),
        "setting": fingerprint(setting="no_physics"),
        "config_sha256": fingerprint(BenchmarkConfig().with_updates(reward={"physics_penalty": 2.5})),
    }
    for field, changed in variants.items():
        assert protocol_id(changed) != reference, field
        assert protocol_difference(fingerprint(), changed) == field


@pytest.mark.parametrize(
    "updates",
    [{"market": {"max_burn_rate": 0.3}}, {"episode_steps": 12}, {"discrete_levels": 3}, {"no_physics_penalty": True}],
)
def test_the_task_configuration_is_hashed(updates: dict) -> None:
    assert protocol_id(fingerprint(BenchmarkConfig().with_updates(**updates))) != protocol_id(fingerprint())


def test_paths_budgets_and_action_modes_do_not_change_the_id() -> None:
    config = BenchmarkConfig().with_updates(output_dir="elsewhere", data_dir="/data", training={"timesteps": 5})
    assert protocol_id(fingerprint(config)) == protocol_id(fingerprint())
    assert protocol_id(fingerprint(action_modes={"dqn": "discrete"})) == protocol_id(fingerprint())


def test_episode_seed_rules_are_named() -> None:
    assert [episode_seed_rule_name(rule) for rule in EPISODE_SEED_RULES.values()] == list(EPISODE_SEED_RULES)
    assert episode_seed_rule_name(independent_episode_seeds) == "independent"
    assert episode_seed_rule_name(lambda s, e: []) == "custom:<lambda>"


def test_units_of_one_grid_merge_and_others_are_refused() -> None:
    units = [
        fingerprint(run_seeds=[s], action_modes={p: "continuous"}) for s, p in [(3, "ppo"), (1, "sac"), (2, "ppo")]
    ]
    merged = merge_fingerprints(units)
    assert merged["run_seeds"] == [1, 2, 3] and merged["action_modes"] == {"ppo": "continuous", "sac": "continuous"}
    assert protocol_id(merged) == protocol_id(fingerprint(run_seeds=[1, 2, 3]))
    with pytest.raises(ValueError, match="protocol field 'episodes'"):
        merge_fingerprints([fingerprint(), fingerprint(episodes=3)])


def test_a_run_records_its_fingerprint_and_equal_protocols_get_equal_ids(tiny_dataset: Path, tmp_path: Path) -> None:
    def agent(observation):
        return [0.5, 0.5, 0.5]

    first = solarchain_eval.evaluate(agent, data=tiny_dataset, seeds=[7], episodes=2, out=tmp_path / "a")
    second = solarchain_eval.evaluate("myopic", data=tiny_dataset, seeds=[7], episodes=2, out=tmp_path / "b")
    third = solarchain_eval.evaluate(agent, data=tiny_dataset, seeds=[7], episodes=3)
    assert first.protocol_id == second.protocol_id != third.protocol_id
    meta = json.loads((tmp_path / "a" / "run_metadata.json").read_text())
    assert meta["protocol"]["dataset_sha256"] == meta["dataset"]["files"]
    assert meta["protocol"]["run_seeds"] == [7] and meta["protocol"]["episodes"] == 2
    assert meta["protocol"]["env"] == "SolarChainEval-v0" and meta["protocol"]["setting"] == "main"
