"""The grid-root machinery ``paper`` and ``sweep`` share (experiments/grid_root.py)."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

from solarchain_eval.experiments import grid_root, paper
from solarchain_eval.experiments.grid import GridSpec, plan_units, scoped
from solarchain_eval.experiments.units import DONE_MARKER, UNIT_FILE, model_digest

EXPERIMENTS = Path(grid_root.__file__).parent


def _from_imports(module: str) -> list[tuple[str, str]]:
    """(relative module, name) of every ``from .x import name`` in experiments/<module>.py."""
    tree = ast.parse((EXPERIMENTS / f"{module}.py").read_text(encoding="utf-8"))
    return [
        (node.module or "", alias.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.level == 1
        for alias in node.names
    ]


@pytest.mark.parametrize("module", ["paper", "sweep"])
def test_paper_and_sweep_share_grid_root_and_not_each_others_privates(module):
    imports = _from_imports(module)
    assert not [(m, n) for m, n in imports if n.startswith("_")], "a private name of another module"
    assert not [m for m, _ in imports if m in ("paper", "sweep")], "paper and sweep import each other"
    assert {"locked", "grid_identity", "unit_task", "make_executor"} <= {n for m, n in imports if m == "grid_root"}


def test_grid_error_and_identity_still_import_from_paper():
    assert paper.GridError is grid_root.GridError
    assert paper.grid_identity is grid_root.grid_identity
    assert paper.model_file is grid_root.model_file


def _done(directory: Path, record: dict) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    (directory / UNIT_FILE).write_text(json.dumps(record))
    (directory / DONE_MARKER).write_text("{}")


@pytest.mark.parametrize("scope", ["", "points/p1"])
def test_an_eval_unit_whose_model_changed_is_undone_in_a_root_or_a_sweep_point(tmp_path, scope):
    spec = GridSpec(timesteps=10, episodes=1, seeds=(5,), settings=("main",), policies=("ppo",))
    units = plan_units(spec)
    units = scoped(units, scope) if scope else units
    train, evaluation = units
    assert (train.kind, evaluation.kind, evaluation.policy) == ("train", "eval", "ppo")
    _done(train.directory(tmp_path), {})
    model = train.directory(tmp_path) / grid_root.model_file("sb3")
    model.write_bytes(b"the model")
    _done(evaluation.directory(tmp_path), {"model_sha256": model_digest({"ppo": model})})
    assert grid_root.finished_units(tmp_path, units, spec) == {train.name, evaluation.name}

    model.write_bytes(b"another model")  # retrained since the evaluation
    assert grid_root.finished_units(tmp_path, units, spec) == {train.name}
    assert not (evaluation.directory(tmp_path) / DONE_MARKER).exists()


def test_a_root_holding_another_grid_names_what_differs(tmp_path):
    identity = {"episodes": 2, "config": {"reward": {"physics_penalty": 1.0}}}
    assert grid_root.identity_conflict(tmp_path, identity) is None  # an empty root
    grid_root.write_metadata(tmp_path, {"identity": identity, "status": "running"})
    assert grid_root.identity_conflict(tmp_path, identity) is None
    changed = {"episodes": 3, "config": {"reward": {"physics_penalty": 1.0}}}
    assert grid_root.identity_conflict(tmp_path, changed) == ["episodes: 2 -> 3"]
    assert grid_root.read_metadata(tmp_path)["status"] == "running"


def test_a_busy_root_is_a_grid_error_naming_the_command(tmp_path):
    with (
        grid_root.locked(tmp_path, "sweep"),
        pytest.raises(grid_root.GridError, match="another 'sweep' run is using"),
        grid_root.locked(tmp_path, "sweep"),
    ):
        pass
    with grid_root.locked(tmp_path):  # released
        pass
