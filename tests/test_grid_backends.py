"""The grid's two extensions together: the JAX backend (units carry a backend) and sweeps
(units carry a scope), and PPO-Lagrangian, which only the SB3 backend trains."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from solarchain_eval.cli import app
from solarchain_eval.experiments.grid import GridSpec, plan_units, scoped


def test_scoped_units_keep_their_backend_and_unscope_back():
    spec = GridSpec.from_preset("smoke", backend="jax", settings=("main",))
    units = plan_units(spec)
    trains = [u for u in units if u.kind == "train"]
    assert trains and all(u.backend == "jax" for u in trains)
    moved = scoped(units, "p01")
    assert [u.backend for u in moved] == [u.backend for u in units]
    assert all(u.name.startswith("p01/") for u in moved)
    assert all(d.startswith("p01/") for u in moved for d in u.depends_on)
    assert [u.unscoped() for u in moved] == units


def test_ppo_lagrangian_is_refused_with_the_jax_backend():
    GridSpec.from_preset("smoke", policies=("ppo-lag", "static"), settings=("main",)).validate()  # sb3: fine
    spec = GridSpec.from_preset("smoke", backend="jax", policies=("ppo-lag", "static"), settings=("main",))
    with pytest.raises(ValueError, match="ppo-lag trains with the sb3 backend only"):
        spec.validate()


def test_train_cli_refuses_ppo_lag_on_jax(tmp_path):
    result = CliRunner().invoke(
        app, ["train", "--algo", "ppo-lag", "--cost-limit", "10", "--backend", "jax", "--out", str(tmp_path / "m")]
    )
    assert result.exit_code == 2, result.output
    assert "Stable-Baselines3 only" in result.output
    assert not (tmp_path / "m").exists()
