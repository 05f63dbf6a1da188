"""The JAX backend trains in compiled chunks with a checkpoint after each: a run interrupted
after a chunk and resumed ends with the same train state, bit for bit, as one that was not,
which is the same as the whole training in one compiled call and as rejax's own ``train`` (the
trainer before chunks); a checkpoint that does not belong to the training is ignored. ``paper --backend jax`` resumes a killed train unit from its last
chunk and shows the trainings' progress in plain lines when stderr is not a terminal.

SAC is the algorithm under test: its state is the largest (the replay buffer) and its training
consumes random keys at every step. 600 steps: 100 of random play, then 500 updates.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("jax", reason="the JAX backend is optional: pip install -e '.[jax]'")
pytest.importorskip("rejax", reason="the JAX backend is optional: pip install -e '.[jax]'")

import jax  # noqa: E402

from solarchain_eval.training.jax_trainer import JaxTrainSpec, seed_dirs, train_jax  # noqa: E402

SEEDS = (3, 4)
STEPS, CHUNK = 600, 150  # four chunks
CLI = [sys.executable, "-c", "from solarchain_eval.cli import main; main()"]


class Interrupted(Exception):
    """Raised from the progress callback: the run stops after that chunk's checkpoint."""


def _leaves(states) -> list[np.ndarray]:
    leaves = jax.tree.leaves(states)
    return [
        np.asarray(jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x) for x in leaves
    ]


def _paths(states) -> list[str]:
    return [jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_flatten_with_path(states)[0]]


def _assert_same_state(a, b) -> None:
    # rejax makes a new state class per traced init, so the trees are compared by their paths
    paths = _paths(a)
    assert paths == _paths(b) and len(paths) > 80
    different = [p for p, x, y in zip(paths, _leaves(a), _leaves(b), strict=True) if not np.array_equal(x, y)]
    assert different == [], f"{len(different)} of {len(paths)} leaves differ, e.g. {different[:3]}"


@pytest.fixture(scope="module")
def runs(tmp_path_factory, tiny_dataset) -> dict:
    """The same SAC training uninterrupted, interrupted after chunk 2 and resumed, and in one call."""
    from solarchain_eval.config import BenchmarkConfig
    from solarchain_eval.envs.jax_env import SolarChainJaxEnv, make_env_params
    from solarchain_eval.training.jax_algorithm import compile_training
    from solarchain_eval.training.jax_chunks import ChunkedTraining

    root = tmp_path_factory.mktemp("jax-resume")
    spec = JaxTrainSpec("sac", SEEDS, STEPS, data_dir=tiny_dataset, chunk_steps=CHUNK)
    whole_reports, resumed_reports, notes = [], [], []
    whole = train_jax(spec, seed_dirs(root / "whole", SEEDS), on_progress=whole_reports.append)

    def stop_after_chunk_2(progress) -> None:
        if progress.chunk == 2:
            raise Interrupted

    with pytest.raises(Interrupted):
        train_jax(spec, seed_dirs(root / "resumed", SEEDS), on_progress=stop_after_chunk_2)
    checkpoint = root / "resumed" / "checkpoints" / "jax_chunks.npz"
    assert checkpoint.is_file() and not (root / "resumed" / "seed_3" / "jax_model.msgpack").exists()
    shutil.copy(checkpoint, root / "after_chunk_2.npz")
    resumed = train_jax(
        spec, seed_dirs(root / "resumed", SEEDS), on_progress=resumed_reports.append, on_note=notes.append
    )
    env = SolarChainJaxEnv(make_env_params(tiny_dataset, action_mode="continuous"))
    one_loop = ChunkedTraining("sac", SEEDS, STEPS, env, BenchmarkConfig(), CHUNK)
    one_loop.compile()
    rejax_train, _ = compile_training("sac", SEEDS, STEPS, env, BenchmarkConfig())
    return {
        "rejax": rejax_train(one_loop.keys)[0],
        "root": root,
        "whole": whole,
        "resumed": resumed,
        "whole_reports": whole_reports,
        "resumed_reports": resumed_reports,
        "notes": notes,
        "training": one_loop,
        "saved": root / "after_chunk_2.npz",
    }


def test_resumed_training_equals_the_uninterrupted_one_bit_for_bit(runs, tiny_dataset):
    from solarchain_eval.evaluation.runner import EvaluationSpec, run_evaluation

    whole, resumed, root = runs["whole"], runs["resumed"], runs["root"]
    assert resumed.resumed_from == 300 and resumed.steps_trained == 300 and whole.resumed_from is None
    assert runs["notes"] == [
        f"resuming from the checkpoint at step 300 ({root / 'resumed' / 'checkpoints' / 'jax_chunks.npz'})"
    ]
    assert [p.chunk for p in runs["resumed_reports"]] == [3, 4]
    # every leaf: parameters, optimiser states, replay buffer, RNG keys, env states, step counter
    _assert_same_state(whole.states, resumed.states)
    assert np.asarray(whole.states.replay_buffer.full).all()  # the buffer (600 rows) holds every step
    metrics = []
    for name in ("whole", "resumed"):
        directory = root / name
        assert not (directory / "checkpoints").exists()  # removed once the models are written
        meta = json.loads((directory / "seed_3" / "train_metadata.json").read_text())
        assert meta["complete"] and meta["timesteps_done"] == STEPS and meta["chunk_steps"] == CHUNK
        assert meta["resumed_from"] == (300 if name == "resumed" else None)
        out = root / f"eval-{name}"
        spec = EvaluationSpec(
            policies=["sac"],
            run_seeds=[20260511],
            episodes=2,
            data_dir=tiny_dataset,
            models={"sac": directory / "seed_3"},
        )
        run_evaluation(spec, out, command=["test"])
        metrics.append(pd.read_csv(out / "metrics.csv"))
    for seed in SEEDS:
        model = f"seed_{seed}/jax_model.msgpack"
        assert (root / "whole" / model).read_bytes() == (root / "resumed" / model).read_bytes()
    pd.testing.assert_frame_equal(metrics[0], metrics[1])
    assert metrics[0]["cumulative_reward"].notna().all() and len(metrics[0]) == 2


def test_chunked_training_equals_the_whole_training_in_one_call_and_rejax_train(runs):
    """The simple paths: the whole budget in one call of the compiled loop (no host round trips),
    and rejax's own ``train``, one program that also computes the initial state."""
    training, whole = runs["training"], runs["whole"]
    assert training.plan.chunks == 4 and training.plan.chunk_steps == CHUNK
    _assert_same_state(training.tree(training.run()), whole.states)
    # a chunk size that does not divide the budget: the same program, other stops
    state = training.initial_state()
    for iterations in (250, 250, 100):
        state = training.advance(state, iterations)
    _assert_same_state(training.tree(state), whole.states)
    # rejax's train returns every leaf per seed; the trainer keeps seed-invariant ones once
    paths, shared = _paths(whole.states), []
    assert paths == _paths(runs["rejax"])
    for path, ours, theirs in zip(paths, _leaves(whole.states), _leaves(runs["rejax"]), strict=True):
        if ours.shape != theirs.shape:
            assert theirs.shape == (len(SEEDS), *ours.shape), path
            shared.append(path)
            theirs = theirs[0]
        assert np.array_equal(ours, theirs), path
    assert ".global_step" in shared and ".replay_buffer.index" in shared and ".rng" not in shared
    reports = runs["whole_reports"]
    assert [(p.chunk, p.chunks, p.steps_done, p.total_steps) for p in reports] == [
        (k, 4, 150 * k, STEPS) for k in (1, 2, 3, 4)
    ]
    assert reports[-1].eta_s == 0 and all(p.steps_per_s > 0 for p in reports)
    # 25 episodes of 24 hours per seed; the recent return is the mean of each env's last ten
    returns = jax.device_get(whole.states.episode_returns)
    assert np.all(np.asarray(returns.finished) == STEPS // 24) and np.shape(returns.recent) == (len(SEEDS), 1, 10)
    assert reports[-1].recent_return == pytest.approx(float(np.mean(returns.recent)), rel=1e-6)
    assert -30 < reports[-1].recent_return < 0 and reports[0].recent_return != reports[-1].recent_return


def test_a_checkpoint_of_another_training_or_a_broken_one_is_ignored(runs, tmp_path):
    from solarchain_eval.training.jax_chunks import config_sha256, load_checkpoint, run_chunks

    training, saved = runs["training"], runs["saved"]
    with np.load(saved) as stored:
        meta = json.loads(str(stored["meta"]))
        arrays = {name: stored[name] for name in stored.files}
    assert meta["chunk"] == 2 and meta["iterations_done"] == 300
    state, _, why = load_checkpoint(saved, training.template, meta["config_sha256"])
    assert why is None and int(training.tree(state).global_step) == 300
    _, _, why = load_checkpoint(saved, training.template, config_sha256({"seeds": [5, 6]}))
    assert "another training" in why
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(saved.read_bytes()[:5000])
    assert "cannot be read" in load_checkpoint(truncated, training.template, meta["config_sha256"])[2]
    shrunk = tmp_path / "shrunk.npz"
    buffer_leaf = next(k for k, v in arrays.items() if k != "meta" and v.shape == (len(SEEDS), STEPS))
    np.savez(shrunk, **{**arrays, buffer_leaf: arrays[buffer_leaf][:, :10]})
    assert "does not fit" in load_checkpoint(shrunk, training.template, meta["config_sha256"])[2]
    # through the trainer: noted, then trained from the start (not from the foreign state)
    foreign = tmp_path / "jax_chunks.npz"
    shutil.copy(saved, foreign)
    notes = []
    run = run_chunks(training, foreign, config_sha256({"seeds": [5, 6]}), on_note=notes.append)
    assert len(notes) == 1 and notes[0].startswith(f"ignoring the checkpoint {foreign}: it belongs to another training")
    assert run.resumed_from is None and run.chunks_run == 4
    _assert_same_state(run.states, runs["whole"].states)


def _cli(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=900, env={**os.environ, **(env or {})})


def test_paper_resumes_a_killed_jax_train_unit_from_its_last_chunk(tiny_dataset, tmp_path):
    """A worker killed right after chunk 1's checkpoint; the same command again continues there."""
    seeds = "20260511,20260512"
    unit = tmp_path / "root" / "units" / "train" / "dqn-main-20260511+20260512"
    args = (
        "paper", "--backend", "jax", "--preset", "smoke", "--settings", "main", "--policies", "static,dqn",
        "--seeds", seeds, "--chunk-steps", "100", "--workers", "2", "--data", str(tiny_dataset),
        "--out", str(tmp_path / "root"), "--no-report",
    )  # fmt: skip
    killed = _cli(*args, env={"SOLARCHAIN_TEST_KILL_AT": "jax-chunk-1"})
    assert killed.returncode == 1 and "worker process died" in killed.stderr
    assert (unit / "checkpoints" / "jax_chunks.npz").is_file() and not (unit / "DONE").exists()
    again = _cli(*args)
    assert again.returncode == 0, again.stderr
    log = (unit / "unit.log").read_text()
    assert "resuming from the checkpoint at step 100" in log and "trained 300 / 300 steps" in log
    assert "trained 100 / 300 steps" not in log.split("resuming")[1]  # chunk 1 was not trained again
    # stderr is a pipe here: one plain progress line per chunk, from the worker through the driver
    lines = [line for line in again.stderr.splitlines() if line.startswith("train/dqn-main-")]
    assert any("resuming from the checkpoint at step 100" in line for line in lines)
    progress = [line for line in lines if "steps/s per model" in line]
    assert [line.split(": ")[1].split(" steps")[0] for line in progress] == ["200 / 300", "300 / 300"]
    assert all("recent return" in line and "ETA" in line for line in progress)
    assert not (unit / "checkpoints").exists()
    # the resumed group equals the same training uninterrupted, at another chunk size
    alone = _cli(
        "train", "--backend", "jax", "--algo", "dqn", "--seeds", seeds, "--timesteps", "300",
        "--data", str(tiny_dataset), "--out", str(tmp_path / "alone"),
    )  # fmt: skip
    assert alone.returncode == 0, alone.stderr
    for seed in seeds.split(","):
        model = f"seed_{seed}/jax_model.msgpack"
        assert (unit / model).read_bytes() == (tmp_path / "alone" / model).read_bytes()


@pytest.mark.parametrize(
    "args",
    [
        ("train", "--algo", "ppo", "--chunk-steps", "100"),
        ("paper", "--preset", "smoke", "--chunk-steps", "100"),
        ("bench-train", "--algos", "sac", "--chunk-steps", "0"),
    ],
)
def test_chunk_steps_is_refused_without_the_jax_backend(args, tmp_path):
    from typer.testing import CliRunner

    from solarchain_eval.cli import app

    out = () if args[0] == "bench-train" else ("--out", str(tmp_path / "out"))
    result = CliRunner().invoke(app, [*args, *out])
    assert result.exit_code == 2, result.output
    assert "--chunk-steps" in result.output and "--backend jax" in result.output
    assert not (tmp_path / "out").exists()
