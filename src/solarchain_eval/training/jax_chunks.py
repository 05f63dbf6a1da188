"""JAX training in compiled chunks, with a checkpoint of the whole train state after each chunk.

Two compiled programs, both ``vmap``-ed over the seeds: ``init`` (the seeds' keys to their
initial train states) and ``advance`` (train states and an iteration count to the train states
that many training iterations later, one ``fori_loop`` of rejax's ``train_iteration``). The
trainer calls ``advance`` once per chunk and gets the carried state back in Python between
chunks: parameters, optimiser states, replay buffer, RNG keys, environment states, the step
counter and the episode returns (:mod:`.jax_episodes`). It reports progress there and writes
the state to ``jax_chunks.npz`` (atomically), so that a killed training continues from its
last chunk.

The iteration count is an argument of ``advance``, not a constant: every chunk, the last
(shorter) one and a whole training in one call run the same compiled program, so the trained
parameters do not depend on the chunk size nor on where a run was interrupted. The state is
laid out as in rejax's own ``train`` (``jit(vmap(train))``), where the parts that do not depend
on the seed's key (the step counter, the optimisers' step counts, the replay buffer's write
position, ...) are one value for all seeds rather than one per seed: batched, the step counter
would turn rejax's ``lax.cond`` on it into a select that computes both branches, which is about
10 % slower for SAC and compiles to other roundings. Laid out the same way, the chunks compute
exactly what rejax's ``train`` computes, bit for bit (``tests/test_jax_resume.py``).
"""

from __future__ import annotations

import hashlib
import json
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ..common.atomic_files import atomic_write_with
from ..evaluation.rundir import kill_point
from .jax_algorithm import iteration_steps, make_algo, rejax_config, seed_keys, use_compilation_cache
from .jax_progress import DEFAULT_CHUNK_STEPS, ChunkProgress, recent_return

CHECKPOINT_FILE = "jax_chunks.npz"
#: Bumped when the checkpoint's layout changes (an older one is then ignored).
CHECKPOINT_FORMAT = 1


@dataclass(frozen=True)
class ChunkPlan:
    """How a training's iterations split into chunks (env steps are per model)."""

    steps_per_iteration: int
    total_iterations: int
    chunk_iterations: int

    @property
    def total_steps(self) -> int:
        return self.total_iterations * self.steps_per_iteration

    @property
    def chunk_steps(self) -> int:
        return self.chunk_iterations * self.steps_per_iteration

    @property
    def chunks(self) -> int:
        return -(-self.total_iterations // self.chunk_iterations)

    def chunk_of(self, iterations_done: int) -> int:
        """Chunks completed after ``iterations_done`` iterations (a partial one counts)."""
        return -(-iterations_done // self.chunk_iterations)

    def next_stop(self, iterations_done: int) -> int:
        """The iteration count at the end of the chunk that ``iterations_done`` is in."""
        return min((iterations_done // self.chunk_iterations + 1) * self.chunk_iterations, self.total_iterations)


def plan_chunks(algo: str, settings: dict[str, Any], timesteps: int, chunk_steps: int | None = None) -> ChunkPlan:
    """Chunks of ``chunk_steps`` env steps per model (default :data:`DEFAULT_CHUNK_STEPS`),
    rounded up to whole training iterations (PPO: 2,048-step rollouts; DQN: 4 envs)."""
    per_iteration = iteration_steps(algo, settings)
    total = -(-int(timesteps) // per_iteration)
    wanted = int(chunk_steps) if chunk_steps else DEFAULT_CHUNK_STEPS[algo]
    if wanted < 1:
        raise ValueError(f"chunk_steps must be at least 1, got {wanted}")
    return ChunkPlan(per_iteration, total, min(max(-(-wanted // per_iteration), 1), total))


class ChunkedTraining:
    """The compiled ``init`` and ``advance`` programs of one algorithm for one seed group.

    States passed between them are flat lists of the train state's leaves (rejax makes a new
    state class each time it builds one, so the tree is rebuilt by :meth:`tree`); a leaf that
    is the same for every seed has no seed axis (:func:`seed_invariant_leaves`).

    Parameters
    ----------
    algo, seeds, timesteps, env, config
        As for :func:`~.jax_algorithm.compile_training` (``env``: the task's JAX env).
    chunk_steps : int, optional
        Env steps per model in one chunk (default :data:`DEFAULT_CHUNK_STEPS`).
    buffer_timesteps : int, optional
        Size SAC's and DQN's replay buffer for a training of this many steps.
    """

    def __init__(
        self,
        algo: str,
        seeds: tuple[int, ...],
        timesteps: int,
        env: Any,
        config: Any,
        chunk_steps: int | None = None,
        buffer_timesteps: int | None = None,
    ) -> None:
        self.algo, self.seeds = algo, tuple(int(s) for s in seeds)
        self.instance = make_algo(algo, env, config, timesteps, buffer_timesteps=buffer_timesteps)
        self.plan = plan_chunks(algo, rejax_config(algo, config, timesteps, buffer_timesteps), timesteps, chunk_steps)
        self.keys = seed_keys(self.seeds)
        self._treedef: Any = None
        self._init: Any = None
        self._advance: Any = None

    def compile(self) -> float:
        """Compile both programs (or load them from the persistent cache); returns seconds (0
        when they are compiled already)."""
        import warnings

        if self._advance is not None:
            return 0.0
        use_compilation_cache()
        instance = self.instance
        start = time.perf_counter()
        with warnings.catch_warnings():
            # rejax asks for int64 indices, which JAX truncates to int32 without x64: harmless here.
            warnings.filterwarnings("ignore", message="Explicitly requested dtype int64")
            self._treedef = jax.tree.structure(jax.eval_shape(instance.init_state, self.keys[0]))
            axes = [None if shared else 0 for shared in seed_invariant_leaves(instance, self.keys)]

            def init(key: jax.Array) -> list[jax.Array]:
                return jax.tree.leaves(instance.init_state(key))

            def advance(leaves: list[jax.Array], iterations: jax.Array) -> list[jax.Array]:
                ts = jax.tree.unflatten(self._treedef, leaves)
                return jax.tree.leaves(jax.lax.fori_loop(0, iterations, lambda _, t: instance.train_iteration(t), ts))

            self._init = jax.jit(jax.vmap(init, out_axes=axes)).lower(self.keys).compile()
            advance_batch = jax.vmap(advance, in_axes=(axes, None), out_axes=axes)
            self._advance = jax.jit(advance_batch).lower(self._init.out_info, np.int32(0)).compile()
        return time.perf_counter() - start

    @property
    def template(self) -> list[Any]:
        """The state's leaves' shapes and dtypes (``ShapeDtypeStruct``)."""
        return self._init.out_info

    def tree(self, leaves: list[Any]) -> Any:
        """The train state (rejax's) of a flat list of leaves."""
        return jax.tree.unflatten(self._treedef, leaves)

    def initial_state(self) -> list[jax.Array]:
        return self._init(self.keys)

    def advance(self, leaves: list[jax.Array], iterations: int) -> list[jax.Array]:
        """``iterations`` training iterations further (waits for the result)."""
        return jax.block_until_ready(self._advance(leaves, np.int32(iterations)))

    def run(self, iterations: int | None = None) -> list[jax.Array]:
        """The whole training (or its first ``iterations``) in one call: the simple path."""
        return self.advance(self.initial_state(), self.plan.total_iterations if iterations is None else iterations)


def seed_invariant_leaves(instance: Any, keys: jax.Array) -> tuple[bool, ...]:
    """Which leaves of ``instance``'s train state ``jit(vmap(train))`` keeps as one value for
    all seeds: those that never depend on a seed's key, found as JAX's ``vmap`` finds them
    (tracing a training loop under ``vmap`` and asking which results carry the seed axis).

    JAX has no public way to ask whether a value carries the ``vmap`` axis; should its private
    ``BatchTracer`` move, every leaf is kept per seed (a correct training, about 10 % slower for
    SAC and rounded differently from rejax's ``train``), with a warning.
    """
    try:
        from jax._src.interpreters.batching import BatchTracer
    except ImportError:  # pragma: no cover - depends on the JAX version
        import warnings

        warnings.warn("cannot tell seed-invariant leaves with this JAX version: every leaf kept per seed", stacklevel=2)
        return tuple(False for _ in jax.tree.leaves(jax.eval_shape(instance.init_state, keys[0])))
    found: list[bool] = []

    def probe(key: jax.Array) -> Any:
        ts = jax.lax.fori_loop(0, 2, lambda _, t: instance.train_iteration(t), instance.init_state(key))
        found.extend(not isinstance(leaf, BatchTracer) for leaf in jax.tree.leaves(ts))
        return ts

    jax.eval_shape(jax.vmap(probe), keys)
    return tuple(found)


def config_sha256(record: dict[str, Any]) -> str:
    """The hash a checkpoint carries of the training it belongs to."""
    text = json.dumps({"format": CHECKPOINT_FORMAT, **record}, sort_keys=True, default=list)
    return hashlib.sha256(text.encode()).hexdigest()


def _is_key(dtype: Any) -> bool:
    return jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)


def host_leaves(state: Any) -> list[np.ndarray]:
    """The state's leaves as numpy arrays (PRNG keys as their raw ``uint32`` data)."""
    leaves = jax.tree.leaves(state)
    keys = {i: jax.random.key_data(x) for i, x in enumerate(leaves) if _is_key(x.dtype)}
    fetched = jax.device_get([keys.get(i, x) for i, x in enumerate(leaves)])
    return [np.asarray(x) for x in fetched]


def save_checkpoint(path: Path, state: Any, meta: dict[str, Any]) -> Path:
    """Write every leaf of ``state`` and ``meta`` (JSON) to ``path`` atomically."""
    arrays = {f"leaf_{i:05d}": x for i, x in enumerate(host_leaves(state))}
    arrays["meta"] = np.asarray(json.dumps(meta))

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as handle:
            np.savez(handle, **arrays)

    return atomic_write_with(path, write)


def load_checkpoint(path: Path, template: Any, sha256: str) -> tuple[Any, dict[str, Any], str | None]:
    """``(state, meta, None)`` from ``path``, or ``(None, {}, why)`` when it cannot be used here.

    It is refused when unreadable, written for another training (``meta["config_sha256"]``
    differs from ``sha256``) or when its leaves do not match ``template``'s.
    """
    try:
        with np.load(path, allow_pickle=False) as stored:
            meta = json.loads(str(stored["meta"]))
            if meta.get("format") != CHECKPOINT_FORMAT or meta.get("config_sha256") != sha256:
                return None, {}, "it belongs to another training (other settings, seeds, data or format)"
            specs = jax.tree.leaves(template)
            leaves = [stored[f"leaf_{i:05d}"] for i in range(len(specs))]
            if f"leaf_{len(specs):05d}" in stored.files:
                return None, {}, "it holds more state than this training has"
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:  # a truncated or foreign file
        return None, {}, f"it cannot be read ({type(error).__name__}: {error})"
    restored = []
    for i, (spec, leaf) in enumerate(zip(specs, leaves, strict=True)):
        value = jax.random.wrap_key_data(leaf) if _is_key(spec.dtype) else leaf
        if value.shape != spec.shape or value.dtype != spec.dtype:
            return None, {}, f"its state does not fit this training (leaf {i}: {value.shape} {value.dtype})"
        restored.append(value)
    return jax.tree.unflatten(jax.tree.structure(template), restored), meta, None


@dataclass(frozen=True)
class ChunkRun:
    """What one call of :func:`run_chunks` did.

    ``states`` is the final train state of all seeds (rejax's state class): a leaf has a
    leading seed axis unless it is the same for every seed (:func:`seed_invariant_leaves`).
    """

    states: Any
    compile_s: float
    train_s: float
    checkpoint_s: float
    chunks_run: int
    resumed_from: int | None  # env steps per model at the resume, None from scratch


def run_chunks(
    training: ChunkedTraining,
    checkpoint: Path | None,
    sha256: str,
    *,
    on_progress: Callable[[ChunkProgress], None] | None = None,
    on_note: Callable[[str], None] | None = None,
) -> ChunkRun:
    """Train chunk by chunk, resuming from ``checkpoint`` where it holds this training.

    After each chunk the state is written to ``checkpoint`` (unless None), then
    ``on_progress`` is called; an exception raised there stops the training after that
    chunk's checkpoint (as a kill would). ``on_note`` receives one-line messages: a resume, or
    a checkpoint ignored and why.
    """
    note = on_note or (lambda text: None)
    compile_s = training.compile()
    plan, state, done, resumed_from = training.plan, None, 0, None
    if checkpoint is not None and Path(checkpoint).is_file():
        state, meta, why = load_checkpoint(Path(checkpoint), training.template, sha256)
        if state is None:
            note(f"ignoring the checkpoint {checkpoint}: {why}; training from the start")
        else:
            done = int(meta["iterations_done"])
            resumed_from = done * plan.steps_per_iteration
            note(f"resuming from the checkpoint at step {resumed_from:,} ({checkpoint})")
    if state is None:
        state = training.initial_state()
    train_s = checkpoint_s = 0.0
    chunks_run, start_done = 0, done
    while done < plan.total_iterations:
        stop = plan.next_stop(done)
        started = time.perf_counter()
        state = training.advance(state, stop - done)
        done, chunks_run = stop, chunks_run + 1
        chunk = plan.chunk_of(done)
        if checkpoint is not None:
            saved = time.perf_counter()
            meta = {
                "format": CHECKPOINT_FORMAT,
                "config_sha256": sha256,
                "chunk": chunk,
                "iterations_done": done,
                "steps_done": done * plan.steps_per_iteration,
                "chunk_steps": plan.chunk_steps,
                "versions": {"jax": jax.__version__},
            }
            save_checkpoint(Path(checkpoint), state, meta)
            checkpoint_s += time.perf_counter() - saved
            kill_point(f"jax-chunk-{chunk}")  # crash tests: SIGKILL right after this chunk's checkpoint
        train_s += time.perf_counter() - started
        if on_progress is not None:
            on_progress(_progress(training, state, done, start_done, train_s, resumed_from))
    return ChunkRun(training.tree(state), compile_s, train_s, checkpoint_s, chunks_run, resumed_from)


def _progress(
    training: ChunkedTraining, state: Any, done: int, start_done: int, train_s: float, resumed_from: int | None
) -> ChunkProgress:
    plan = training.plan
    returns = jax.device_get(training.tree(state).episode_returns)
    per_s = (done - start_done) * plan.steps_per_iteration / max(train_s, 1e-9)
    remaining = (plan.total_iterations - done) * plan.steps_per_iteration
    return ChunkProgress(
        algo=training.algo,
        seeds=training.seeds,
        chunk=plan.chunk_of(done),
        chunks=plan.chunks,
        steps_done=done * plan.steps_per_iteration,
        total_steps=plan.total_steps,
        recent_return=recent_return(returns.recent, returns.finished),
        steps_per_s=per_s,
        eta_s=remaining / per_s if per_s > 0 else None,
        resumed_from=resumed_from,
    )
