"""Arithmetic back-ends for the market functions: Python floats or numpy arrays.

The market dynamics are written once against this small interface. ``SCALAR`` runs them on
Python floats (the single environment: no per-step numpy overhead), ``BATCH`` on float64
arrays (the vector environment). Both evaluate the same IEEE double operations in the same
order, so a sub-environment of the vector env reproduces the single env bit for bit.

``_F1``/``_F3`` round Python floats to float32 (struct packing); :mod:`.actions` uses them for
the float32 parts of the step. An operation on two float32 values evaluated in float64 and then
rounded to float32 equals the float32 operation (53 >= 2·24 + 2 bits, so double rounding is
innocuous for +, -, ×, ÷).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any

import numpy as np

_F1 = struct.Struct("f")
_F3 = struct.Struct("3f")


def _clip_scalar(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else (hi if x > hi else x)


class ScalarOps:
    """Python-float back-end. Per-city values are tuples (one float per city)."""

    maximum = staticmethod(max)
    minimum = staticmethod(min)
    clip = staticmethod(_clip_scalar)

    @staticmethod
    def per_city(formula: Any, per_env: tuple, city_columns: tuple) -> list:
        """``formula(a, b, share, trust)`` for each city; a list of floats."""
        a, b = per_env
        shares, trusts = city_columns
        return [formula(a, b, share, trust) for share, trust in zip(shares, trusts, strict=True)]

    @staticmethod
    def city_variance(city_values: list) -> float:
        n = len(city_values)
        if 0 < n < 8:  # numpy sums fewer than 8 items left to right
            total = city_values[0]
            for value in city_values[1:]:
                total += value
            mean = total / n
            first = city_values[0] - mean
            total = first * first
            for value in city_values[1:]:
                deviation = value - mean
                total += deviation * deviation
            return total / n
        return numpy_order_variance(city_values)


class BatchOps:
    """numpy float64-array back-end: one element per sub-env; per-city values are (C, N)."""

    maximum = staticmethod(np.maximum)
    minimum = staticmethod(np.minimum)

    @staticmethod
    def clip(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
        return np.minimum(np.maximum(x, lo), hi)

    @staticmethod
    def per_city(formula: Any, per_env: tuple, city_columns: tuple) -> np.ndarray:
        """``formula`` on (C, N) city arrays (per-env operands broadcast along rows); (C, N)."""
        return formula(*per_env, *city_columns)

    @staticmethod
    def city_variance(city_values: np.ndarray) -> np.ndarray:
        """numpy.var's operations per sub-env, with the (C, N) arrays' rows as the cities."""
        n = city_values.shape[0]
        if n == 0:
            return np.zeros(city_values.shape[1:])
        # Below 8 rows numpy's axis-0 sum adds the rows left to right, like its 1-D reduction of
        # each column (checked by the tests); from 8 rows on the pairwise order differs.
        row_sum = (lambda x: x.sum(axis=0)) if n < 8 else (lambda x: numpy_order_sum(list(x)))
        deviation = city_values - row_sum(city_values) / n
        return row_sum(deviation * deviation) / n


SCALAR = ScalarOps()
BATCH = BatchOps()


def numpy_order_sum(values: Sequence[Any]) -> Any:
    """Sum ``values`` (floats, or equal-shape arrays) in the order ``numpy.add.reduce`` uses.

    numpy sums a 1-D float64 array pairwise: fewer than 8 items left to right, up to 128 items
    in 8 interleaved partial sums, larger blocks split in halves (multiples of 8). Reproducing
    that order keeps per-city reductions identical to the original release's ``np.var``.
    """
    n = len(values)
    if n == 0:
        return 0.0
    if n < 8:
        total = values[0]
        for value in values[1:n]:
            total = total + value
        return total
    if n <= 128:
        partial = list(values[:8])
        stop = n - (n % 8)
        for i in range(8, stop, 8):
            for j in range(8):
                partial[j] = partial[j] + values[i + j]
        total = ((partial[0] + partial[1]) + (partial[2] + partial[3])) + (
            (partial[4] + partial[5]) + (partial[6] + partial[7])
        )
        for value in values[stop:n]:
            total = total + value
        return total
    half = n // 2
    half -= half % 8
    return numpy_order_sum(values[:half]) + numpy_order_sum(values[half:])


def numpy_order_variance(values: Sequence[Any]) -> Any:
    """Population variance in ``numpy.var``'s order of operations."""
    n = len(values)
    if n == 0:
        return 0.0
    mean = numpy_order_sum(values) / n
    squares = [(value - mean) * (value - mean) for value in values]
    return numpy_order_sum(squares) / n
