"""Grid units as Ray tasks (``paper --ray-address``); ray is the optional extra ``[ray]``.

Each unit is one Ray task with ``num_cpus=1``. A task first checks whether its node sees the
grid root: the driver writes a random token to ``ROOT/.grid-token`` and the task compares it.

- Shared filesystem (or a single machine): the task runs the unit in place, exactly like a
  local worker (train units resume from their checkpoints).
- No shared filesystem: the driver ships the dataset (once, through Ray's object store) and
  the unit's model files with the task; the task runs the unit in a temporary directory and
  returns its files, which the driver writes into ROOT (each file atomically, ``DONE`` last).

Either way the units land in ROOT exactly as with the local pool.
"""

from __future__ import annotations

import hashlib
import os
import secrets
import shutil
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..common.atomic_files import atomic_write_bytes
from ..common.errors import NamesOptions, ServiceError
from .units import UnitResult, UnitTask, collect_files, execute_unit, write_done

TOKEN_FILE = ".grid-token"


class RayUnavailableError(NamesOptions, ServiceError, RuntimeError):
    """``--ray-address`` was given but ray is not installed or the cluster cannot be reached."""


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise RayUnavailableError.about(
            "{opt_ray_address} needs ray: pip install -e '.[ray]' in a clone of the repository"
        ) from None
    return ray


def dataset_bundle(data_dir: Path) -> dict[str, bytes]:
    """Every file of a dataset directory (any task's: its CSVs and manifest), to ship to Ray nodes."""
    return {path.name: path.read_bytes() for path in sorted(Path(data_dir).iterdir()) if path.is_file()}


def _materialize_dataset(bundle: dict[str, bytes]) -> Path:
    """Write a shipped dataset once per node into the temp dir (keyed by its content)."""
    digest = hashlib.sha256(b"".join(hashlib.sha256(bundle[k]).digest() for k in sorted(bundle))).hexdigest()[:16]
    target = Path(tempfile.gettempdir()) / "solarchain-eval-ray-data" / digest
    if target.is_dir():  # published whole by the rename below
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{digest}.", dir=target.parent))
    for name, data in bundle.items():
        (staging / name).write_bytes(data)
    try:
        os.replace(staging, target)
    except OSError:  # another task on this node got there first
        shutil.rmtree(staging, ignore_errors=True)
    return target


def _run_remote(task: UnitTask, token_path: str, token: str, boxed_data: list, models: dict[str, bytes]) -> tuple:
    """The Ray task body: run in place if this node sees ROOT, else in a temporary directory."""
    try:
        shared = Path(token_path).read_text(encoding="utf-8") == token
    except OSError:
        shared = False
    if shared:
        return execute_unit(task), None
    ray = _import_ray()
    data_dir = _materialize_dataset(ray.get(boxed_data[0]))
    with tempfile.TemporaryDirectory(prefix="solarchain-unit-") as tmp:
        model_paths = {}
        for name, data in models.items():
            path = Path(tmp) / "models" / f"{name}.zip"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
            model_paths[name] = path
        local = replace(task, unit_dir=Path(tmp) / "unit", data_dir=data_dir, model_paths=model_paths)
        result = execute_unit(local, mark_done=False)
        files = collect_files(local.unit_dir)
    return replace(result, log=None), files


class RayExecutor:
    """Submit units as Ray tasks to ``address`` ("auto", "ray://host:port", or "local" to start
    a Ray instance on this machine); an already initialised Ray session is used as it is.

    ``transfer="always"`` ships files even when the nodes share ROOT (used by the tests).
    """

    def __init__(
        self, address: str, root: Path, data_dir: Path, *, transfer: str = "auto", workers: int | None = None
    ) -> None:
        ray = self._ray = _import_ray()
        if not ray.is_initialized():
            try:
                if address == "local":
                    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
                else:
                    ray.init(address=address, log_to_driver=False)
            except Exception as error:
                raise RayUnavailableError(f"cannot connect to the Ray cluster at '{address}': {error}") from None
        self.capacity = max(int(ray.cluster_resources().get("CPU", 1)), 1)
        self._root = Path(root)
        self._token = secrets.token_hex(16) if transfer == "auto" else "ship-files"
        token_path = self._root / TOKEN_FILE
        token_path.write_text(self._token if transfer == "auto" else secrets.token_hex(16), encoding="utf-8")
        self._token_path = str(token_path.resolve())
        # One shipped bundle per dataset directory (a sweep's points use several).
        self._data: dict[str, list] = {str(Path(data_dir)): [ray.put(dataset_bundle(data_dir))]}
        self._remote = ray.remote(num_cpus=1, max_retries=0)(_run_remote)
        self._pending: dict[Any, UnitTask] = {}

    def submit(self, task: UnitTask) -> None:
        models = {name: Path(path).read_bytes() for name, path in task.model_paths.items()}
        key = str(Path(task.data_dir))
        if key not in self._data:
            self._data[key] = [self._ray.put(dataset_bundle(task.data_dir))]
        ref = self._remote.remote(task, self._token_path, self._token, self._data[key], models)
        self._pending[ref] = task

    def wait(self) -> list[UnitResult]:
        ray = self._ray
        ready, _ = ray.wait(list(self._pending), num_returns=1)
        results = []
        for ref in ready:
            task = self._pending.pop(ref)
            try:
                result, files = ray.get(ref)
            except Exception as error:  # the task's worker or node died
                results.append(
                    UnitResult(task.unit.name, False, 0.0, f"Ray task failed: {type(error).__name__}: {error}")
                )
                continue
            if files is not None:
                result = self._install(task, result, files)
            results.append(result)
        return results

    def _install(self, task: UnitTask, result: UnitResult, files: dict[str, bytes]) -> UnitResult:
        unit_dir = Path(task.unit_dir)
        for rel, data in files.items():
            atomic_write_bytes(unit_dir / rel, data)
        log = str(unit_dir / "unit.log")
        if result.ok:
            write_done(unit_dir, task.unit.name, result.wall_s, result.cpu_s)
        return replace(result, log=log)

    def abort(self) -> list[str]:
        names = [task.unit.name for task in self._pending.values()]
        for ref in self._pending:
            self._ray.cancel(ref, force=True)
        self._pending.clear()
        return names

    def close(self) -> None:
        (self._root / TOKEN_FILE).unlink(missing_ok=True)
