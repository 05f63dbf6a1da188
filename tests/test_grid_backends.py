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


def test_jax_grid_trains_each_algorithm_and_setting_as_one_seed_group(tmp_path):
    from solarchain_eval.experiments.grid import eval_model_path

    spec = GridSpec.from_preset("paper", backend="jax")
    units = plan_units(spec)
    trains = [u for u in units if u.kind == "train"]
    # SAC first (the longest), then PPO and DQN; main before no_physics; every seed in each group
    assert [(u.policy, u.setting) for u in trains] == [
        ("sac", "main"), ("sac", "no_physics"), ("ppo", "main"), ("ppo", "no_physics"),
        ("dqn", "main"), ("dqn", "no_physics"),
    ]  # fmt: skip
    assert all(u.seed_group == spec.seeds and u.seed == spec.seeds[0] for u in trains)
    names = {u.name for u in trains}
    evals = [u for u in units if u.kind == "eval" and u.depends_on]
    assert evals and all(u.depends_on[0] in names for u in evals)
    llm_sac = next(u for u in evals if u.policy == "sac" and u.setting == "llm" and u.seed == spec.seeds[1])
    group = "+".join(map(str, spec.seeds))
    assert llm_sac.depends_on == (f"train/sac-main-{group}",)
    path = eval_model_path(tmp_path, llm_sac, "jax", "jax_model.msgpack")
    assert path == tmp_path / "units" / "train" / f"sac-main-{group}" / f"seed_{spec.seeds[1]}" / "jax_model.msgpack"
    # the SB3 grid keeps one unit (and one model directory) per seed
    sb3 = plan_units(GridSpec.from_preset("paper"))
    assert sum(u.kind == "train" for u in sb3) == 3 * len(trains)
    sb3_sac = next(u for u in sb3 if u.name == f"eval/sac-llm-{spec.seeds[1]}")
    assert eval_model_path(tmp_path, sb3_sac, "sb3", "model.zip") == (
        tmp_path / "units" / "train" / f"sac-main-{spec.seeds[1]}" / "model.zip"
    )


def test_the_wall_time_estimate_charges_a_seed_group_once():
    from solarchain_eval.perf.train_bench import UnitTimes, estimate_paper_wall_time

    times = UnitTimes({"ppo": 1000.0, "sac": 100.0, "dqn": 1000.0}, 5.0, {"static": 1.0}, "test")
    jax = estimate_paper_wall_time(times, 2, GridSpec.from_preset("paper", backend="jax"))
    sb3 = estimate_paper_wall_time(times, 2, GridSpec.from_preset("paper"))
    per_model = 5.0 + 300_000 / 100.0
    assert jax["train_sac_cpu_s"] == 2 * per_model  # two groups (main, no_physics) of three seeds
    assert sb3["train_sac_cpu_s"] == 6 * per_model


def test_bench_train_on_a_subset_of_algorithms_prints_its_figures_without_an_estimate(monkeypatch):
    # --algos sac measures SAC and says why there is no preset estimate, instead of failing
    # after the measurement (the estimate needs all three algorithms).
    from typer.testing import CliRunner

    from solarchain_eval.cli import app
    from solarchain_eval.perf import train_bench as bench_train
    from solarchain_eval.perf.env_bench import Throughput

    monkeypatch.setattr(bench_train, "solarchain_env", lambda algo, data_dir: None)
    monkeypatch.setattr(
        bench_train, "training_steps_per_s", lambda *a, **k: Throughput("SAC training", "steps/s", (123.0,))
    )
    monkeypatch.setattr(
        bench_train, "measured_unit_times", lambda data_dir, rates: bench_train.UnitTimes(rates, 1.0, {}, "test")
    )
    result = CliRunner().invoke(app, ["bench-train", "--algos", "sac", "--no-ceiling", "--repeats", "1"])
    assert result.exit_code == 0, result.output
    assert "123" in result.output and "no paper estimate" in result.output and "missing ppo, dqn" in result.output


def test_bench_train_sb3_measurement_leaves_no_sb3_log_directories(tmp_path, monkeypatch):
    """SB3's default logger set-up makes an empty ``SB3-<time>`` directory in the temp folder
    on every ``learn()``; the measurement hands it a logger with no outputs instead."""
    import tempfile

    from solarchain_eval.perf import train_bench as bench_train

    monkeypatch.delenv("SB3_LOGDIR", raising=False)  # conftest points raw SB3 calls elsewhere
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setattr(bench_train, "WARMUP_STEPS", {"dqn": 8})
    speed = bench_train.training_steps_per_s("dqn", bench_train.TrivialEnv("discrete"), 16, 2)
    assert len(speed.samples) == 2 and all(s > 0 for s in speed.samples)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith("SB3-")] == []
