"""Dispatching grid units to executors in dependency order.

Executors: :class:`InlineExecutor` (this process, ``--workers 1``), :class:`LocalPool` (``K``
spawned worker processes) and :class:`~.ray_executor.RayExecutor` (Ray tasks). Each runs
:func:`~.units.execute_unit`; the driver loop :func:`run_units` submits a unit once every unit it
depends on is done, and on a failure either stops (in-flight units are interrupted and redone
by the next run) or, with ``keep_going``, records it and skips the units that depend on it.

Local workers are started with the ``spawn`` method, use one torch thread, ignore Ctrl-C (the
driver stops them) and, on Linux, are killed by the kernel when the driver dies
(``PR_SET_PDEATHSIG``), so a killed run never leaves workers writing into the grid. They are not
*daemonic* processes, which multiprocessing forbids to start processes of their own: an eval unit
of an isolated user agent (``--isolate``) starts the agent's process from its worker. The pool
closes them itself, at :meth:`LocalPool.close` or at the interpreter's exit. When there
are at least two workers and no more than the CPUs the process may use, each worker is pinned
to a CPU of its own (:func:`worker_cpus`): XLA keeps a third of a second core busy beside a JAX
training for no gain in speed (measured: the same steps/s pinned to one core), and unpinned
that time is taken from the other worker.
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing as mp
import os
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from typing import Protocol

from ..common.cpus import available_cpus, can_pin, pin_to_cpu
from .grid import Unit
from .units import UnitProgress, UnitResult, UnitTask, execute_unit

#: Receives the running units' progress (JAX trainings' chunks) as they come.
ProgressHandler = Callable[[UnitProgress], None]


class Executor(Protocol):
    capacity: int

    def submit(self, task: UnitTask) -> None: ...

    def wait(self) -> list[UnitResult]: ...

    def abort(self) -> list[str]: ...

    def close(self) -> None: ...


class InlineExecutor:
    """Runs units one at a time in this process."""

    capacity = 1

    def __init__(self, on_progress: ProgressHandler | None = None) -> None:
        self._queue: list[UnitTask] = []
        self.on_progress = on_progress

    def submit(self, task: UnitTask) -> None:
        self._queue.append(task)

    def wait(self) -> list[UnitResult]:
        return [execute_unit(self._queue.pop(0), on_progress=self.on_progress)]

    def abort(self) -> list[str]:
        names = [t.unit.name for t in self._queue]
        self._queue.clear()
        return names

    def close(self) -> None:
        return None


def _die_with_parent(parent_pid: int) -> None:
    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG: the kernel kills us when the parent dies
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)


def worker_cpus(workers: int) -> list[int | None]:
    """The CPU each of ``workers`` local workers is pinned to (None: not pinned).

    Pinned only where it cannot hurt: two or more workers, and no more than the CPUs this
    process may run on (``os.sched_getaffinity``); where that is unknown, nothing is pinned.
    """
    cpus = available_cpus()
    if not can_pin() or not 2 <= workers <= len(cpus):
        return [None] * workers
    return cpus[:workers]


def _worker_main(conn: Connection, parent_pid: int, cpu: int | None = None) -> None:
    _die_with_parent(parent_pid)
    if cpu is not None:  # before any library starts its threads: they inherit the affinity
        pin_to_cpu(cpu)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[name] = "1"
    while True:
        try:
            task = conn.recv()
        except EOFError:
            return
        if task is None:
            return
        conn.send(execute_unit(task, on_progress=conn.send))  # progress messages, then the result


@dataclass
class _Worker:
    process: mp.process.BaseProcess
    conn: Connection
    cpu: int | None = None
    task: UnitTask | None = None


@dataclass
class LocalPool:
    """``workers`` long-lived worker processes, one unit at a time each.

    A worker sends its unit's :class:`~.units.UnitProgress` messages before the result; they
    go to ``on_progress`` as :meth:`wait` reads them.
    """

    workers: int
    context: str = "spawn"
    on_progress: ProgressHandler | None = None
    _pool: list[_Worker] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.capacity = self.workers
        self._ctx = mp.get_context(self.context)
        self._pool = [self._start(cpu) for cpu in worker_cpus(self.workers)]
        # Before multiprocessing's own exit handler, which would wait for non-daemonic workers forever.
        atexit.register(self.close)

    def _start(self, cpu: int | None) -> _Worker:
        parent, child = self._ctx.Pipe()
        process = self._ctx.Process(
            target=_worker_main, args=(child, os.getpid(), cpu), daemon=False, name="solarchain-unit"
        )
        process.start()
        child.close()
        return _Worker(process, parent, cpu)

    def submit(self, task: UnitTask) -> None:
        worker = next(w for w in self._pool if w.task is None)
        worker.conn.send(task)
        worker.task = task

    def wait(self) -> list[UnitResult]:
        """The results that came in (none when only progress did)."""
        busy = [w for w in self._pool if w.task is not None]
        ready = wait([w.conn for w in busy] + [w.process.sentinel for w in busy])
        results = []
        for worker in busy:
            task = worker.task
            assert task is not None
            if worker.conn in ready or worker.process.sentinel in ready:
                if worker.conn.poll():
                    try:
                        message = worker.conn.recv()
                    except EOFError:
                        message = None
                    if isinstance(message, UnitProgress):  # the unit runs on; its result comes later
                        if self.on_progress is not None:
                            self.on_progress(message)
                        continue
                    if message is not None:
                        results.append(message)
                        worker.task = None
                        continue
                worker.process.join(timeout=5)
                code = worker.process.exitcode
                results.append(UnitResult(task.unit.name, False, 0.0, f"worker process died (exit code {code})", None))
                self._pool[self._pool.index(worker)] = self._start(worker.cpu)
        return results

    def abort(self) -> list[str]:
        names = [w.task.unit.name for w in self._pool if w.task is not None]
        self.close()
        return names

    def close(self) -> None:
        for worker in self._pool:
            if worker.process.is_alive():
                if worker.task is None:
                    with contextlib.suppress(BrokenPipeError, OSError):
                        worker.conn.send(None)
                    worker.process.join(timeout=2)
                if worker.process.is_alive():
                    worker.process.kill()
            worker.process.join(timeout=5)
            worker.conn.close()
        self._pool = []
        atexit.unregister(self.close)


@dataclass
class RunReport:
    """What :func:`run_units` did."""

    finished: list[UnitResult] = field(default_factory=list)
    failed: list[UnitResult] = field(default_factory=list)
    blocked: list[str] = field(default_factory=list)
    interrupted: list[str] = field(default_factory=list)
    stopped: bool = False


def run_units(
    units: Sequence[Unit],
    done: set[str],
    make_task: Callable[[Unit], UnitTask],
    executor: Executor,
    *,
    keep_going: bool = False,
    on_result: Callable[[UnitResult], None] | None = None,
    on_start: Callable[[Unit], None] | None = None,
) -> RunReport:
    """Run every unit not in ``done`` once its dependencies are done.

    ``done`` is updated in place. Without ``keep_going`` the first failure stops the run and the
    units in flight are interrupted (listed in ``RunReport.interrupted``).
    """
    report = RunReport()
    pending = [u for u in units if u.name not in done]
    bad: set[str] = set()
    in_flight: dict[str, Unit] = {}
    try:
        while pending or in_flight:
            for unit in list(pending):
                if any(dep in bad for dep in unit.depends_on):
                    pending.remove(unit)
                    bad.add(unit.name)
                    report.blocked.append(unit.name)
                elif len(in_flight) < executor.capacity and all(dep in done for dep in unit.depends_on):
                    pending.remove(unit)
                    task = make_task(unit)
                    if on_start is not None:
                        on_start(unit)
                    executor.submit(task)
                    in_flight[unit.name] = unit
            if not in_flight:
                report.blocked.extend(u.name for u in pending)  # unreachable dependencies
                break
            for result in executor.wait():
                in_flight.pop(result.unit, None)
                if result.ok:
                    done.add(result.unit)
                    report.finished.append(result)
                else:
                    bad.add(result.unit)
                    report.failed.append(result)
                if on_result is not None:
                    on_result(result)
                if not result.ok and not keep_going:
                    report.stopped = True
                    report.interrupted = executor.abort()
                    return report
    except BaseException:
        report.interrupted = executor.abort()
        raise
    finally:
        executor.close()
    return report
