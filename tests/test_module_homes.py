"""Names that moved out of a module too long to read keep their old import paths, and each has one
home: the module that defines it (``runner``, ``verify``, ``envs.env`` and ``sb3_trainer`` were
split by concern)."""

from __future__ import annotations

import importlib

import pytest

#: (the old import path, the name, the module that now defines it)
MOVED = [
    ("solarchain_eval.evaluation.runner", "EvaluationSpec", "solarchain_eval.evaluation.run_spec"),
    ("solarchain_eval.evaluation.runner", "EvaluationOutcome", "solarchain_eval.evaluation.run_spec"),
    ("solarchain_eval.evaluation.runner", "resolved_config", "solarchain_eval.evaluation.run_spec"),
    ("solarchain_eval.evaluation.runner", "dataset_provenance", "solarchain_eval.evaluation.run_spec"),
    ("solarchain_eval.evaluation.runner", "make_policies", "solarchain_eval.evaluation.agent_setup"),
    ("solarchain_eval.evaluation.runner", "agent_requests_of", "solarchain_eval.evaluation.agent_setup"),
    ("solarchain_eval.evaluation.runner", "check_agents", "solarchain_eval.evaluation.agent_setup"),
    ("solarchain_eval.evaluation.runner", "check_agent_requests", "solarchain_eval.evaluation.agent_setup"),
    ("solarchain_eval.evaluation.runner", "run_evaluation", "solarchain_eval.evaluation.runner"),
    ("solarchain_eval.evaluation.verify", "PolicyVerification", "solarchain_eval.evaluation.verify_outcome"),
    ("solarchain_eval.evaluation.verify", "RunVerification", "solarchain_eval.evaluation.verify_outcome"),
    ("solarchain_eval.evaluation.verify", "rerun_policy", "solarchain_eval.evaluation.verify_replay"),
    ("solarchain_eval.evaluation.verify", "Difference", "solarchain_eval.evaluation.verify_checks"),
    ("solarchain_eval.evaluation.verify", "VerifyError", "solarchain_eval.evaluation.verify_checks"),
    ("solarchain_eval.evaluation.verify", "first_difference", "solarchain_eval.evaluation.verify_checks"),
    ("solarchain_eval.evaluation.verify", "written_row", "solarchain_eval.evaluation.verify_checks"),
    ("solarchain_eval.evaluation.verify", "choose_episodes", "solarchain_eval.evaluation.verify_plan"),
    ("solarchain_eval.evaluation.verify", "default_seed", "solarchain_eval.evaluation.verify_plan"),
    ("solarchain_eval.evaluation.verify", "replay_plan", "solarchain_eval.evaluation.verify_plan"),
    ("solarchain_eval.evaluation.verify", "VerifyOptions", "solarchain_eval.evaluation.verify"),
    ("solarchain_eval.evaluation.verify", "verify_run", "solarchain_eval.evaluation.verify"),
    ("solarchain_eval.envs.env", "step_info", "solarchain_eval.envs.step_info"),
    ("solarchain_eval.envs.env", "env_config", "solarchain_eval.envs.market_setup"),
    ("solarchain_eval.envs.env", "resolve_config", "solarchain_eval.envs.market_setup"),
    ("solarchain_eval.envs.env", "resolve_table", "solarchain_eval.envs.market_setup"),
    ("solarchain_eval.envs.env", "setup_market", "solarchain_eval.envs.market_setup"),
    ("solarchain_eval.envs.env", "market_inputs", "solarchain_eval.envs.market_setup"),
    ("solarchain_eval.envs.env", "start_hours", "solarchain_eval.envs.market_setup"),
    ("solarchain_eval.training.sb3_trainer", "TrainSpec", "solarchain_eval.training.sb3_spec"),
    ("solarchain_eval.training.sb3_trainer", "TrainOutcome", "solarchain_eval.training.sb3_spec"),
    ("solarchain_eval.training.sb3_trainer", "hyperparameters", "solarchain_eval.training.sb3_spec"),
    ("solarchain_eval.training.sb3_trainer", "dqn_learning_starts", "solarchain_eval.training.sb3_spec"),
    ("solarchain_eval.training.sb3_trainer", "quiet_logger", "solarchain_eval.training.sb3_session"),
    ("solarchain_eval.training.sb3_trainer", "set_torch_threads", "solarchain_eval.training.sb3_session"),
    ("solarchain_eval.training.sb3_trainer", "train", "solarchain_eval.training.sb3_trainer"),
    ("solarchain_eval.training.sb3_trainer", "differences", "solarchain_eval.training.sb3_trainer"),
]


@pytest.mark.parametrize(("old", "name", "home"), MOVED, ids=[f"{o.rsplit('.', 1)[1]}.{n}" for o, n, _ in MOVED])
def test_a_moved_name_is_its_homes_object_under_the_old_path(old, name, home):
    value = getattr(importlib.import_module(old), name)
    assert value is getattr(importlib.import_module(home), name)
    assert value.__module__ == home  # defined there, not a copy or a second definition


@pytest.mark.parametrize(
    ("old", "name", "value"),
    [
        ("solarchain_eval.evaluation.verify", "VERIFIED", "verified"),
        ("solarchain_eval.evaluation.verify", "DIFFERS", "differs"),
        ("solarchain_eval.evaluation.verify", "CANNOT_REBUILD", "cannot rebuild"),
        ("solarchain_eval.evaluation.verify", "DEFAULT_VERIFY_EPISODES", 3),
        ("solarchain_eval.evaluation.verify_outcome", "VERIFIED", "verified"),
        ("solarchain_eval.training.sb3_trainer", "TRAIN_LOG_FILE", "training_log.csv"),
        ("solarchain_eval.training.sb3_trainer", "TRAIN_METADATA_FILE", "train_metadata.json"),
        ("solarchain_eval.training.sb3_trainer", "CHECKPOINT_DIR", "checkpoints"),
        ("solarchain_eval.training.sb3_trainer", "DEFAULT_CHECKPOINT_EVERY", 25_000),
        ("solarchain_eval.envs.env", "STEP_INFO_KEYS", ("reward", "absolute_hour", "episode_start_hour", "hour")),
    ],
)
def test_the_constants_keep_their_path_and_value(old, name, value):
    got = getattr(importlib.import_module(old), name)
    assert (got[: len(value)] if isinstance(value, tuple) else got) == value
