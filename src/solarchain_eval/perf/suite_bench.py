"""What a suite costs (``solarchain-eval bench-suite``): its datasets built cold, then its evaluation.

Two figures, each beside a reference measured in the same process, so that a ratio can be
compared across machines:

- **build**: every dataset of every shipped suite built from the package into a fresh, empty
  cache, as a first ``evaluate --suite`` builds them (a suite built online, ``paper-cities``,
  only when named); the reference is the paper's default
  dataset built once into another fresh cache;
- **evaluation**: the default policies (Static, Random, Myopic) over the held-out suite at the
  protocol ``evaluate --suite heldout`` uses by default (the paper's three run seeds × 30
  episodes per entry, every run directory and the suite root written, as the command writes
  them); the reference is the same policies, seeds and episodes on the paper's dataset (one run
  directory).

Datasets and suites are reached only through the task interface: the suites'
:meth:`~solarchain_eval.tasks.suites.SuiteEntry.data_dir` builds an entry's dataset into the
package's cache, so the benchmark points the cache (``$SOLARCHAIN_CACHE_DIR``) at a directory of
its own while it runs. Each measurement is wall time and this process's CPU time
(``time.process_time``; the evaluation runs in this process): on a shared machine the CPU time
is the steadier figure. The suite figures are measured first, so they carry the process's
one-time costs (imports, reading the packaged weather files), as a user's first run does.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from ..config import BenchmarkConfig
from ..evaluation.rundir import check_target
from ..evaluation.runner import EvaluationSpec, run_evaluation
from ..evaluation.suite_run import run_suite
from ..protocol import PAPER_SEEDS
from ..tasks.registry import DEFAULT_TASK, get_task
from ..tasks.suites import BUILTIN_SUITES, Suite, get_suite

#: The issue's targets, on a 2-core machine: every shipped suite's datasets built, and the three
#: baselines over the whole held-out suite, each within a minute.
BUILD_TARGET_S = 60.0
EVALUATION_TARGET_S = 60.0
#: The suite the evaluation target is set for.
HELDOUT_SUITE = "heldout"
#: The environment variable that moves the package's cache (``common/cache.py``).
CACHE_ENV = "SOLARCHAIN_CACHE_DIR"


@dataclass(frozen=True)
class BuiltDataset:
    """One dataset the build measurement built: the entry that names it, its directory and cost."""

    name: str
    data_dir: str
    wall_s: float
    cpu_s: float


@dataclass(frozen=True)
class SuiteBench:
    """The figures of :func:`measure_suite`; ``*_s`` wall seconds, ``*_cpu_s`` CPU seconds of this process.

    ``complete`` is true when every shipped offline suite was built whole and the held-out suite ran
    whole at its default protocol: only then do the figures stand for the targets.
    """

    built_suites: tuple[str, ...]
    datasets: tuple[BuiltDataset, ...]
    build_s: float
    build_cpu_s: float
    reference_build_s: float
    reference_build_cpu_s: float
    suite: str
    suite_protocol_id: str
    entries: int
    policies: tuple[str, ...]
    run_seeds: int
    episodes_per_seed: int
    episodes: int
    evaluation_s: float
    evaluation_cpu_s: float
    reference_episodes: int
    reference_evaluation_s: float
    reference_evaluation_cpu_s: float
    complete: bool
    cpus: int | None = field(default_factory=os.cpu_count)
    load_1min: tuple[float, float] = (0.0, 0.0)

    @property
    def datasets_built(self) -> int:
        """How many datasets the build measurement built."""
        return len(self.datasets)

    @property
    def build_ratio(self) -> float:
        """Suite datasets' build wall time over the paper dataset's (same run)."""
        return self.build_s / self.reference_build_s

    @property
    def build_cpu_ratio(self) -> float:
        """The same ratio in CPU time."""
        return self.build_cpu_s / self.reference_build_cpu_s

    @property
    def evaluation_ratio(self) -> float:
        """Suite evaluation wall time over the same policies' on the paper dataset (same run)."""
        return self.evaluation_s / self.reference_evaluation_s

    @property
    def evaluation_cpu_ratio(self) -> float:
        """The same ratio in CPU time."""
        return self.evaluation_cpu_s / self.reference_evaluation_cpu_s

    def as_dict(self) -> dict:
        """Every field and ratio, for ``--json``."""
        out = asdict(self)
        out["datasets_built"] = self.datasets_built
        for name in ("build_ratio", "build_cpu_ratio", "evaluation_ratio", "evaluation_cpu_ratio"):
            out[name] = getattr(self, name)
        out["targets_s"] = {"build": BUILD_TARGET_S, "evaluation": EVALUATION_TARGET_S}
        return out


@contextmanager
def cache_at(path: Path | None) -> Iterator[Path]:
    """Point the package's cache at ``path`` (an empty or absent directory, kept), or at a fresh
    temporary directory (removed), for the duration; the previous setting is restored."""
    with tempfile.TemporaryDirectory(prefix="solarchain-bench-cache-") as tmp:
        folder = Path(tmp) if path is None else Path(path)
        if path is not None and folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise ValueError(f"{folder}: the cache must be an empty or absent directory (the builds are timed cold)")
        folder.mkdir(parents=True, exist_ok=True)
        before = os.environ.get(CACHE_ENV)
        os.environ[CACHE_ENV] = str(folder)
        try:
            yield folder
        finally:
            if before is None:
                os.environ.pop(CACHE_ENV, None)
            else:
                os.environ[CACHE_ENV] = before


def first_entries(suite: Suite, entries: int | None) -> Suite:
    """``suite`` with only its first ``entries`` entries (None: all of them)."""
    return suite if entries is None else replace(suite, entries=suite.entries[:entries])


def build_suites(suites: Sequence[Suite]) -> list[BuiltDataset]:
    """Build every entry's dataset of ``suites`` into the current cache, each directory once, timed."""
    built: dict[Path, BuiltDataset] = {}
    for suite in suites:
        for entry in suite.entries:
            started, cpu = time.perf_counter(), time.process_time()
            data_dir = entry.data_dir()  # builds on first use; a directory built already costs nothing
            wall_s, cpu_s = time.perf_counter() - started, time.process_time() - cpu
            if data_dir.resolve() not in built:
                built[data_dir.resolve()] = BuiltDataset(entry.name, str(data_dir), wall_s, cpu_s)
    return list(built.values())


def measure_suite(
    *,
    build: Sequence[str] | None = None,
    suite: str = HELDOUT_SUITE,
    entries: int | None = None,
    seeds: int = len(PAPER_SEEDS),
    episodes: int | None = None,
    cache: Path | None = None,
    out: Path | None = None,
) -> SuiteBench:
    """Build the suites' datasets cold, evaluate ``suite``, and measure both references.

    Parameters
    ----------
    build : sequence of str, optional
        The suites whose datasets are built (default: every shipped suite built offline).
    suite : str
        The suite evaluated (its datasets are built first if ``build`` does not hold it).
    entries : int, optional
        Only the first ``entries`` entries of each suite (a quick check; the targets stand for whole suites).
    seeds, episodes : int
        The first ``seeds`` of the paper's run seeds and the episodes per seed (default: the
        configuration's, as ``evaluate``).
    cache : Path, optional
        Build into this empty directory and keep it (default: a temporary one).
    out : Path, optional
        Write the evaluated suite's root here and keep it (default: a temporary one).
    """
    if not 1 <= seeds <= len(PAPER_SEEDS):
        raise ValueError(f"seeds must be 1..{len(PAPER_SEEDS)}, not {seeds}")
    defaults = BenchmarkConfig().evaluation
    policies = tuple(defaults.policies)
    episodes = defaults.episodes if episodes is None else episodes
    run_seeds = PAPER_SEEDS[:seeds]
    offline = tuple(name for name in BUILTIN_SUITES if not get_suite(name).online)
    names = offline if build is None else tuple(build)
    built_suites = [first_entries(get_suite(name), entries) for name in names]  # unknown names: before any work
    evaluated = first_entries(get_suite(suite), entries)
    if out is not None:
        check_target(out, overwrite=False)  # before any work (run_suite checks it again)
    load_before = os.getloadavg()[0]

    def make_spec(entry, data_dir: Path, everyone: list) -> EvaluationSpec:
        return EvaluationSpec(
            policies=everyone, data_dir=data_dir, task=entry.task, run_seeds=run_seeds, episodes=episodes
        )

    def run(spec: EvaluationSpec, run_dir: Path):
        return run_evaluation(spec, run_dir, command=["bench-suite"], keep_results=False)

    with cache_at(cache), tempfile.TemporaryDirectory(prefix="solarchain-bench-suite-") as tmp:
        started, cpu = time.perf_counter(), time.process_time()
        datasets = build_suites(built_suites)
        build_s, build_cpu_s = time.perf_counter() - started, time.process_time() - cpu
        build_suites([evaluated])  # untimed: nothing to do when the evaluated suite is among the built ones
        started, cpu = time.perf_counter(), time.process_time()
        result = run_suite(
            evaluated, list(policies), make_spec, run, out or Path(tmp) / "suite", command=["bench-suite"]
        )
        evaluation_s, evaluation_cpu_s = time.perf_counter() - started, time.process_time() - cpu
    with cache_at(None), tempfile.TemporaryDirectory(prefix="solarchain-bench-suite-") as tmp:
        task = get_task(DEFAULT_TASK)
        started, cpu = time.perf_counter(), time.process_time()
        paper_dir = task.data_dir(None, None)  # the paper's default dataset, built on first use
        reference_build_s, reference_build_cpu_s = time.perf_counter() - started, time.process_time() - cpu
        spec = EvaluationSpec(policies=list(policies), data_dir=paper_dir, run_seeds=run_seeds, episodes=episodes)
        started, cpu = time.perf_counter(), time.process_time()
        reference = run_evaluation(spec, Path(tmp) / "run", command=["bench-suite"], keep_results=False)
        reference_evaluation_s = time.perf_counter() - started
        reference_evaluation_cpu_s = time.process_time() - cpu
    whole = all(len(s.entries) == len(get_suite(s.name).entries) for s in [*built_suites, evaluated])
    return SuiteBench(
        built_suites=names,
        datasets=tuple(datasets),
        build_s=build_s,
        build_cpu_s=build_cpu_s,
        reference_build_s=reference_build_s,
        reference_build_cpu_s=reference_build_cpu_s,
        suite=evaluated.name,
        suite_protocol_id=result.protocol_id,
        entries=len(evaluated.entries),
        policies=policies,
        run_seeds=len(run_seeds),
        episodes_per_seed=episodes,
        episodes=sum(outcome.episodes for outcome in result.runs.values()),
        evaluation_s=evaluation_s,
        evaluation_cpu_s=evaluation_cpu_s,
        reference_episodes=reference.episodes,
        reference_evaluation_s=reference_evaluation_s,
        reference_evaluation_cpu_s=reference_evaluation_cpu_s,
        complete=whole
        and evaluated.name == HELDOUT_SUITE
        and set(names) >= set(offline)
        and seeds == len(PAPER_SEEDS)
        and episodes == defaults.episodes,
        load_1min=(load_before, os.getloadavg()[0]),
    )
