"""Unpickling a model's parts without running what the pickle names (docs/security.md#learned-models).

A pickle is a program: unpickling calls whatever functions it names, so a crafted model file
can create files or run commands on the machine that loads it. :func:`safe_loads` unpickles
with a :class:`pickle.Unpickler` whose ``find_class`` answers only the names a trained model's
parts are made of: numpy arrays, scalars and generators, a few containers, gymnasium spaces,
and classes of Stable-Baselines3 / sb3-contrib policies, their torch layers and optimizers,
schedules, training-frequency tuples and normalisation statistics. Classes whose construction
allocates what the pickle asks for (replay and rollout buffers) are not among them: SB3 builds
its default one when the entry is replaced. Any other name (a function
such as ``builtins.open`` or ``os.system``, a function pickled by value) is refused, before it
is called, with :class:`UnsafePickle` naming it.
"""

from __future__ import annotations

import importlib
import io
import pickle
from typing import Any

from ..common.errors import RefusedError

#: (module, name) pairs allowed as they are: numpy's array, scalar and generator rebuilders and containers.
_EXACT = {
    *((m, n) for m in ("numpy.core.multiarray", "numpy._core.multiarray") for n in ("_reconstruct", "scalar")),
    *((m, "_frombuffer") for m in ("numpy.core.numeric", "numpy._core.numeric")),
    ("numpy", "ndarray"),
    ("numpy", "dtype"),
    *(("numpy.random._pickle", n) for n in ("__generator_ctor", "__bit_generator_ctor", "__randomstate_ctor")),
    *(("numpy.random._pcg64", n) for n in ("PCG64", "PCG64DXSM")),
    ("numpy.random._mt19937", "MT19937"),
    *(("numpy.random.bit_generator", n) for n in ("SeedSequence", "__pyx_unpickle_SeedSequence")),
    ("numpy.random._philox", "Philox"),
    ("numpy.random._sfc64", "SFC64"),
    ("collections", "OrderedDict"),
    ("collections", "deque"),
    *(("builtins", n) for n in ("set", "frozenset", "slice", "complex", "object", "bytearray")),
}
#: Module prefixes whose *classes* of the kinds :func:`_allowed_class` accepts may be named.
_CLASS_MODULES = ("gymnasium.spaces.", "stable_baselines3.", "sb3_contrib.", "torch.nn.", "torch.optim.")


class UnsafePickle(RefusedError, pickle.UnpicklingError):
    """A pickle that names something a model's parts never need (refused before it is called)."""


def _allowed_class(value: Any) -> bool:
    """A class a trained model is made of (never a function: calling a class builds a value)."""
    if not isinstance(value, type):
        return False
    import gymnasium
    import torch

    kinds: list[type] = [gymnasium.spaces.Space, torch.nn.Module, torch.optim.Optimizer]
    try:
        from stable_baselines3.common.running_mean_std import RunningMeanStd
        from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit
        from stable_baselines3.common.vec_env.vec_normalize import VecNormalize

        kinds += [RunningMeanStd, TrainFreq, TrainFrequencyUnit, VecNormalize]
        from stable_baselines3.common import utils

        kinds += [
            getattr(utils, n) for n in ("FloatSchedule", "ConstantSchedule", "LinearSchedule") if hasattr(utils, n)
        ]
    except ImportError:  # an SB3 without one of these: fewer kinds are allowed
        pass
    return any(issubclass(value, kind) for kind in kinds)


class _Unpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in _EXACT:
            return super().find_class(module, name)
        if module.startswith(_CLASS_MODULES) and "." not in name:
            try:
                value = getattr(importlib.import_module(module), name)
            except (ImportError, AttributeError):
                raise UnsafePickle(f"names {module}.{name}, which does not exist here") from None
            if _allowed_class(value):
                return value
        raise UnsafePickle(f"names {module}.{name}, which a model never needs")

    def persistent_load(self, pid: Any) -> Any:
        raise UnsafePickle("holds a persistent reference (torch storage), which this part never has")


def safe_loads(data: bytes) -> Any:
    """Unpickle ``data`` allowing only a model's kinds of values (module docstring).

    Raises
    ------
    UnsafePickle
        The pickle names a function or class outside the allowed kinds (nothing was called).
    pickle.UnpicklingError, EOFError, ValueError, TypeError
        A damaged pickle.
    """
    return _Unpickler(io.BytesIO(data)).load()
