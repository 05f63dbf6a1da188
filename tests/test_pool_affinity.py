"""Local workers are pinned to a CPU each when there are at least two and no more than the CPUs."""

from __future__ import annotations

import os
import time

import pytest

from solarchain_eval.experiments import pool
from solarchain_eval.experiments.pool import LocalPool, worker_cpus

linux_only = pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="CPU affinity is Linux-only")


@linux_only
@pytest.mark.parametrize(("cpus", "workers", "expected"), [
    ({0, 1}, 2, [0, 1]),
    ({3, 5, 7}, 2, [3, 5]),
    ({0, 1}, 3, [None, None, None]),  # more workers than CPUs: let the kernel share them out
    ({0, 1, 2, 3}, 1, [None]),  # one worker: nothing to keep apart
])  # fmt: skip
def test_worker_cpus(monkeypatch, cpus, workers, expected):
    monkeypatch.setattr(pool.os, "sched_getaffinity", lambda pid: set(cpus))
    assert worker_cpus(workers) == expected


@linux_only
def test_pool_workers_run_on_their_own_cpu():
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        pytest.skip("needs two CPUs")
    workers = LocalPool(2)
    try:
        deadline = time.monotonic() + 60
        seen = []
        for worker in workers._pool:
            while True:  # the worker pins itself as it starts
                seen_now = os.sched_getaffinity(worker.process.pid)
                if len(seen_now) == 1 or time.monotonic() > deadline:
                    break
                time.sleep(0.05)
            seen.append(seen_now)
        assert seen == [{cpus[0]}, {cpus[1]}]
    finally:
        workers.close()
