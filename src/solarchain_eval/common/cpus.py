"""The CPUs this process may run on, and pinning a process to one of them (Linux only)."""

from __future__ import annotations

import os


def available_cpus() -> list[int]:
    """The CPUs this process may use (its affinity mask on Linux; else every CPU)."""
    try:
        return sorted(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return list(range(os.cpu_count() or 1))


def can_pin() -> bool:
    """Whether this platform lets a process pin itself to a CPU."""
    return hasattr(os, "sched_setaffinity")


def pin_to_cpu(cpu: int) -> None:
    """Pin the calling thread, and the threads it starts from now on, to ``cpu``."""
    os.sched_setaffinity(0, {cpu})
