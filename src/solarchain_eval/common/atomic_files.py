"""Atomic file writes: a crash never leaves a file that looks complete."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~_current_umask()  # what open() would give a new file


def _atomic_write(path: Path, write: Callable[[Path], None]) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        with open(tmp, "rb") as handle:
            os.fsync(handle.fileno())
        os.chmod(tmp, _FILE_MODE)  # mkstemp creates files readable by the owner only
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


class AtomicFile:
    """A file written piece by piece that appears at ``path`` complete or not at all.

    The pieces go to a hidden ``.NAME.*.partial`` beside ``path``; :meth:`commit` syncs it and
    renames it into place, :meth:`discard` (or an exception in a ``with`` block) removes it.
    :attr:`handle` is a text handle (UTF-8, newlines as written) or, with ``binary``, a byte handle.
    """

    def __init__(self, path: Path | str, *, binary: bool = False) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".partial", dir=self.path.parent)
        self.tmp = Path(tmp_name)
        self.handle: Any = os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="")

    def commit(self) -> Path:
        self.handle.flush()
        os.fsync(self.handle.fileno())
        self.handle.close()
        os.chmod(self.tmp, _FILE_MODE)  # mkstemp creates files readable by the owner only
        os.replace(self.tmp, self.path)
        return self.path

    def discard(self) -> None:
        self.handle.close()
        self.tmp.unlink(missing_ok=True)

    def __enter__(self) -> AtomicFile:
        return self

    def __exit__(self, kind: object, error: object, trace: object) -> None:
        if not self.handle.closed:
            self.discard()


def atomic_write_with(path: Path | str, write: Callable[[Path], None]) -> Path:
    """Atomically create ``path`` from ``write(tmp_path)`` (for writers that want a path,
    e.g. a library's ``save``): the file appears complete or not at all."""
    return _atomic_write(Path(path), write)


def atomic_write_text(path: Path | str, text: str) -> Path:
    return _atomic_write(Path(path), lambda tmp: tmp.write_text(text, encoding="utf-8"))


def atomic_write_bytes(path: Path | str, data: bytes) -> Path:
    return _atomic_write(Path(path), lambda tmp: tmp.write_bytes(data))


def _non_finite_at(value: Any, where: str = "") -> str | None:
    """The path (``a.b[2]``) of the first NaN or ±inf float inside ``value``, if any."""
    if isinstance(value, float):
        return None if value - value == 0.0 else where or "<top level>"
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, (list, tuple)) else ()
    for key, item in items:
        found = _non_finite_at(item, f"{where}[{key}]" if isinstance(key, int) else f"{where}.{key}".lstrip("."))
        if found:
            return found
    return None


def atomic_write_json(path: Path | str, payload: Any) -> Path:
    """Write strict JSON (a NaN or ±inf is refused, naming where it is: other tools cannot read it)."""
    where = _non_finite_at(payload)
    if where is not None:
        raise ValueError(f"{path}: refusing to write a non-finite number at {where} (strict JSON)")
    text = json.dumps(payload, indent=2, sort_keys=False, default=_json_default, allow_nan=False)
    return atomic_write_text(path, text + "\n")


def atomic_write_csv(path: Path | str, frame: Any, **kwargs: Any) -> Path:
    """Write a pandas frame as CSV (``index=False``) atomically."""
    kwargs.setdefault("index", False)
    return _atomic_write(Path(path), lambda tmp: frame.to_csv(tmp, **kwargs))


def _json_default(value: Any) -> Any:
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot serialise {type(value).__name__} to JSON")


def read_csv_exact(path: Path | str, **kwargs: Any) -> Any:
    """``pandas.read_csv`` with floats parsed exactly (so written floats read back bit for bit).

    pandas 3 parses exactly by default and deprecates ``float_precision``; pandas 2 needs asking.
    """
    import pandas as pd

    if int(pd.__version__.split(".")[0]) < 3:
        kwargs.setdefault("float_precision", "round_trip")
    return pd.read_csv(path, **kwargs)


def sha256_file(path: Path | str) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
