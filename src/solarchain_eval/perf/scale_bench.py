"""Scale benchmark: dataset build, load and env throughput against node and city counts.

For each (cities, nodes per city) pair a synthetic-weather dataset is built into a temporary
directory, loaded (validation plus the hourly table), and stepped by the single env and the
native vector env. Build time should grow about linearly in the node count (one generation
pass per node); env steps/s should not depend on it, since the env reads the hourly table,
which aggregates the nodes (it does depend on the number of cities: per-city rewards).

Build and load are reported as wall time and as this process's CPU time
(``time.process_time``): on a shared machine the CPU time is the figure that compares across
sizes; build time per node is CPU time per node.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from ..protocol import PAPER_SEED
from ..tasks.dataset import dataset_of
from ..tasks.registry import DEFAULT_TASK, get_task
from .env_bench import single_env_steps_per_s, vector_env_steps_per_s


#: The issue's grid: 50, 500 and 5,000 nodes, over 5 and 50 cities.
@dataclass(frozen=True)
class ScaleResult:
    cities: int
    nodes: int
    hours: int
    generation_rows: int
    weather_s: float
    build_s: float
    build_cpu_s: float
    build_ms_per_node: float
    load_s: float
    load_cpu_s: float
    env_steps_per_s: float
    vector_env_steps_per_s: float

    def as_dict(self) -> dict:
        return asdict(self)


def parse_scales(text: str) -> tuple[tuple[int, int], ...]:
    """``"5x10,50x100"`` -> ((5, 10), (50, 100)): cities x nodes per city."""
    scales = []
    for part in text.split(","):
        try:
            cities, nodes = (int(v) for v in part.strip().lower().split("x"))
        except ValueError:
            raise ValueError(f"scale '{part.strip()}' is not CITIESxNODES_PER_CITY (e.g. 5x100)") from None
        if cities < 1 or nodes < 1:
            raise ValueError(f"scale '{part.strip()}': cities and nodes per city must be at least 1")
        scales.append((cities, nodes))
    return tuple(scales)


def measure_scale(
    cities: int,
    nodes_per_city: int,
    *,
    start: str = "2026-04-01",
    end: str = "2026-05-01",
    env_steps: int = 20_000,
    num_envs: int = 256,
    vector_calls: int = 200,
    repeats: int = 3,
    seed: int = PAPER_SEED,
) -> ScaleResult:
    """Build, load and step one synthetic dataset of ``cities`` x ``nodes_per_city`` nodes.

    The solar market's dataset builder and loader, reached through its task; the time zone is the
    builder's default (Asia/Shanghai).
    """
    task = get_task(DEFAULT_TASK)
    builder = dataset_of(task)
    city_list = builder.cities(cities)
    timezone = builder.defaults.timezone
    with tempfile.TemporaryDirectory(prefix="solarchain-scale-") as tmp:
        started = time.perf_counter()
        weather = builder.choose_weather(city_list, start, end, seed=seed, timezone=timezone, source="synthetic")
        weather_s = time.perf_counter() - started
        started, cpu = time.perf_counter(), time.process_time()
        manifest = builder.build(
            weather,
            Path(tmp),
            cities=city_list,
            seed=seed,
            start=start,
            end=end,
            nodes_per_city=nodes_per_city,
            timezone=timezone,
        )
        build_s, build_cpu_s = time.perf_counter() - started, time.process_time() - cpu
        started, cpu = time.perf_counter(), time.process_time()
        table = task.load_data(Path(tmp))
        load_s, load_cpu_s = time.perf_counter() - started, time.process_time() - cpu
        single = single_env_steps_per_s(Path(tmp), env_steps, repeats)
        vector = vector_env_steps_per_s(Path(tmp), num_envs, vector_calls, repeats)
        nodes = cities * nodes_per_city
        return ScaleResult(
            cities=cities,
            nodes=nodes,
            hours=table.hours,
            generation_rows=int(manifest["files"][builder.node_records_file]["rows"]),
            weather_s=weather_s,
            build_s=build_s,
            build_cpu_s=build_cpu_s,
            build_ms_per_node=1000.0 * build_cpu_s / nodes,
            load_s=load_s,
            load_cpu_s=load_cpu_s,
            env_steps_per_s=single.median,
            vector_env_steps_per_s=vector.median,
        )
