"""Action decoding, sanitising and encoding (docs/environment.md#action-space, docs/reproducing.md).

Policies act in normalised space u ∈ [0, 1]^3. Decoding maps u to market units in float32
(α = 0.05 + 0.60 u₁, ℓ = 0.20 + 0.75 u₂, b = 0.20 u₃), then sanitises: clip each float32
component in float32 to its range rounded to float32, then, in float64, if α + ℓ > 0.98, scale
both by 0.98 / (α + ℓ); the executed action is float32. This is what the original release's
``float(np.clip(x, lo, hi))`` does on a float32 scalar under numpy 2: u₁ = 1 decodes to
α = 0.65000004, which clips to float32(0.65) = 0.64999998 (not 0.65). Encoding is the inverse
for policies that think in market units.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import MarketConfig
from .ops import _F1, _F3

_F32 = np.float32


@dataclass(frozen=True)
class ActionCodec:
    """Ranges of (reward ratio α, liquidity ratio ℓ, burn rate b), all dimensionless.

    ``lo``/``hi`` are the ranges as configured (float64); ``lo32``/``width32`` the float32
    decoding constants. Sanitising clips against the bounds rounded to float32 (``lo32`` and
    :attr:`hi32`).
    """

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    lo32: tuple[float, float, float]
    width32: tuple[float, float, float]
    max_total_allocation: float

    def __post_init__(self) -> None:
        # Clip bounds rounded to float32, as Python floats (scalar path) and (3, 1) columns (batches).
        object.__setattr__(self, "hi32", tuple(float(_F32(v)) for v in self.hi))
        object.__setattr__(self, "_lo_column", np.array(self.lo32, dtype=_F32)[:, None])
        object.__setattr__(self, "_hi_column", np.array(self.hi32, dtype=_F32)[:, None])
        object.__setattr__(self, "_width32", tuple(_F32(w) for w in self.width32))
        object.__setattr__(self, "_lo32", tuple(_F32(v) for v in self.lo32))

    @classmethod
    def from_config(cls, market: MarketConfig) -> ActionCodec:
        lo = (market.min_reward_ratio, market.min_liquidity_ratio, 0.0)
        hi = (market.max_reward_ratio, market.max_liquidity_ratio, market.max_burn_rate)
        widths = (hi[0] - lo[0], hi[1] - lo[1], hi[2])
        return cls(
            lo=lo,
            hi=hi,
            lo32=tuple(float(_F32(v)) for v in lo),
            width32=tuple(float(_F32(v)) for v in widths),
            max_total_allocation=market.max_total_allocation,
        )

    # --- single actions ---------------------------------------------------------------------
    def decode(self, action: Any) -> tuple[float, float, float]:
        """Decode one continuous action (array-like of 3) to executed (α, ℓ, b).

        Each float32 operation is evaluated in float64 and rounded to float32, which equals the
        float32 operation itself (53 >= 2·24 + 2 bits); :meth:`decode_batch` performs the same
        operations natively in float32 and the tests check that both agree.
        """
        u = action if isinstance(action, np.ndarray) and action.dtype == _F32 else np.asarray(action, dtype=_F32)
        if u.shape != (3,):
            u = u.reshape(-1)
            if u.shape != (3,):
                raise ValueError(f"a continuous action has 3 components, got shape {np.shape(action)}")
        u0, u1, u2 = u.tolist()
        # NaN -> 0; ±inf and everything else clipped to [0, 1]; -0.0 -> +0.0 like decode_batch's fmax.
        u0 = 0.0 if u0 != u0 or u0 <= 0.0 else (1.0 if u0 > 1.0 else u0)
        u1 = 0.0 if u1 != u1 or u1 <= 0.0 else (1.0 if u1 > 1.0 else u1)
        u2 = 0.0 if u2 != u2 or u2 <= 0.0 else (1.0 if u2 > 1.0 else u2)
        w0, w1, w2 = self.width32
        p0, p1, p2 = _F3.unpack(_F3.pack(u0 * w0, u1 * w1, u2 * w2))
        alpha, ell, burn = _F3.unpack(_F3.pack(self.lo32[0] + p0, self.lo32[1] + p1, p2))
        return self._sanitize_scalar(alpha, ell, burn)

    def _sanitize_scalar(self, alpha: float, ell: float, burn: float) -> tuple[float, float, float]:
        # The inputs are float32 values, so comparing them in float64 with the float32-rounded
        # bounds is the float32 clip itself; the clipped values then scale in float64.
        lo, hi = self.lo32, self.hi32
        alpha = lo[0] if alpha < lo[0] else (hi[0] if alpha > hi[0] else alpha)
        ell = lo[1] if ell < lo[1] else (hi[1] if ell > hi[1] else ell)
        burn = lo[2] if burn < lo[2] else (hi[2] if burn > hi[2] else burn)
        total = alpha + ell
        if total > self.max_total_allocation:
            scale = self.max_total_allocation / total
            alpha, ell = alpha * scale, ell * scale
        return _F3.unpack(_F3.pack(alpha, ell, burn))

    def sanitize(self, alpha: float, ell: float, burn: float) -> tuple[float, float, float]:
        """Sanitise an action in market units; float32 result.

        The inputs are rounded to float32 first (the original release sanitised float32
        arrays on every path: decoded actions, baseline targets, auditor revisions), then
        clipped in float32 and scaled. NaN components are rejected: sanitising is for targets
        a policy computed, not raw outputs.
        """
        values = (float(alpha), float(ell), float(burn))
        if any(v != v for v in values):
            raise ValueError(f"cannot sanitise an action with NaN components: {values}")
        try:
            values = _F3.unpack(_F3.pack(*values))
        except OverflowError:  # beyond float32's range: ±inf, which the clip then bounds
            with np.errstate(over="ignore"):
                values = tuple(np.array(values, dtype=np.float64).astype(_F32).tolist())
        return self._sanitize_scalar(*values)

    def encode(self, alpha: float, ell: float, burn: float) -> np.ndarray:
        """Market-unit target -> normalised float32 action (sanitised first, then clipped)."""
        a, ell_, b = self.sanitize(alpha, ell, burn)
        u = _F3.unpack(_F3.pack(a - self.lo32[0], ell_ - self.lo32[1], b))
        u = _F3.unpack(_F3.pack(u[0] / self.width32[0], u[1] / self.width32[1], u[2] / self.width32[2]))
        return np.clip(np.array(u, dtype=_F32), 0.0, 1.0)

    # --- batches ----------------------------------------------------------------------------
    # Component-major (3, N) float32 arrays and native float32 arithmetic: the same IEEE
    # operations the scalar path emulates, so results are identical (the tests compare both
    # on adversarial inputs).
    def decode_batch(self, actions: Any) -> np.ndarray:
        """Decode (N, 3) normalised actions; returns executed actions as a (3, N) float32 array."""
        u = np.asarray(actions, dtype=_F32)
        if u.ndim != 2 or u.shape[1] != 3:
            raise ValueError(f"a batch of continuous actions has shape (N, 3), got {u.shape}")
        # fmax/fmin ignore NaN: NaN -> 0, -inf -> 0, +inf -> 1, i.e. nan_to_num then clip.
        u = np.ascontiguousarray(u.T)
        np.fmax(u, _F32(0.0), out=u)
        np.fmin(u, _F32(1.0), out=u)
        w0, w1, w2 = self._width32
        market = np.empty_like(u)
        np.multiply(u[0], w0, out=market[0])
        np.multiply(u[1], w1, out=market[1])
        np.multiply(u[2], w2, out=market[2])
        market[0] += self._lo32[0]
        market[1] += self._lo32[1]
        return self.sanitize_batch(market)

    def sanitize_batch(self, actions: np.ndarray) -> np.ndarray:
        """Sanitise a (3, N) batch in market units: clip in float32, scale in float64; (3, N) float32."""
        clipped = np.array(actions, dtype=_F32, order="C")
        np.maximum(clipped, self._lo_column, out=clipped)
        np.minimum(clipped, self._hi_column, out=clipped)
        a = clipped.astype(np.float64)
        # cap / total >= 1 exactly when no scaling is needed, and x * 1.0 == x.
        scale = np.minimum(self.max_total_allocation / (a[0] + a[1]), 1.0)
        a[0] *= scale
        a[1] *= scale
        return a.astype(_F32)

    def discrete_grid(self, levels: int) -> np.ndarray:
        """The normalised grid {0, 1/(k-1), ..., 1}^3 in itertools.product order, float32."""
        values = np.linspace(0.0, 1.0, int(levels), dtype=_F32)
        return np.array(list(itertools.product(values, values, values)), dtype=_F32)

    def discrete_table(self, levels: int) -> list[tuple[float, float, float]]:
        """Executed (α, ℓ, b) of every grid point."""
        return [self.decode(point) for point in self.discrete_grid(levels)]


ACTION_MODES = ("continuous", "discrete")


def check_action_mode(action_mode: str | None) -> str | None:
    """``action_mode`` itself if it is None or one of :data:`ACTION_MODES`, else a ValueError."""
    if action_mode is not None and action_mode not in ACTION_MODES:
        raise ValueError(f"action_mode must be 'continuous' or 'discrete', not {action_mode!r}")
    return action_mode


def initial_action(market: MarketConfig) -> tuple[float, float, float]:
    """a_prev at reset: the configured static action (α, ℓ, b), each rounded to float32.

    The previous action the first step's jitter and the observation's previous α, ℓ refer to.
    """
    return tuple(
        float(_F32(v)) for v in (market.static_reward_ratio, market.static_liquidity_ratio, market.static_burn_rate)
    )


@dataclass(frozen=True, eq=False)
class DiscreteActions:
    """The executed (α, ℓ, b) of each index of ``Discrete(levels**3)``: the one decoding of an index.

    ``table`` holds them as tuples of float32 values (the single env), ``columns`` as a (3, K)
    float32 array (the vector env).
    """

    table: tuple[tuple[float, float, float], ...]
    columns: np.ndarray

    @classmethod
    def from_codec(cls, codec: ActionCodec, levels: int) -> DiscreteActions:
        table = tuple(codec.discrete_table(levels))
        columns = np.array(table, dtype=_F32).T.copy()
        columns.setflags(write=False)
        return cls(table, columns)

    def __len__(self) -> int:
        return len(self.table)

    def decode(self, action: Any) -> tuple[float, float, float]:
        """The executed action of one index (see :func:`discrete_index` for what is accepted)."""
        return self.table[discrete_index(action, len(self.table))]

    def decode_batch(self, actions: Any, num_envs: int) -> np.ndarray:
        """Executed actions of one index per sub-env, as a (3, num_envs) float32 array."""
        return self.columns[:, discrete_indices(actions, len(self.table), num_envs)]


def action_jitter_f32(a: tuple, prev: tuple) -> float:
    """J = |a - a_prev|_1 of float32 actions, in float32 (numpy's order: left to right)."""
    d0, d1, d2 = _F3.unpack(_F3.pack(abs(a[0] - prev[0]), abs(a[1] - prev[1]), abs(a[2] - prev[2])))
    (partial,) = _F1.unpack(_F1.pack(d0 + d1))
    return _F1.unpack(_F1.pack(partial + d2))[0]


def action_jitter_f32_batch(actions: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """J per sub-env of (3, N) float32 action arrays, in float32; returned as float64."""
    d = np.abs(actions - prev)
    return ((d[0] + d[1]) + d[2]).astype(np.float64)


def _is_integer(value: Any) -> bool:
    # bool is an int subclass in Python, but True is not an action index.
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, (int, np.integer)):
        return True
    return isinstance(value, np.ndarray) and value.shape == () and np.issubdtype(value.dtype, np.integer)


def discrete_index(action: Any, n_actions: int) -> int:
    """The index of one discrete action, accepted as ``gymnasium.spaces.Discrete.contains`` would.

    Parameters
    ----------
    action : int, numpy integer scalar or 0-d integer array
        The action; bools, floats, strings, lists and vectors are refused.
    n_actions : int
        Size of the action space (indices ``0 .. n_actions - 1``).

    Raises
    ------
    ValueError
        If ``action`` is not an integer or is out of range.
    """
    if not _is_integer(action):
        raise ValueError(
            f"a discrete action must be an integer in 0..{n_actions - 1}, not {action!r} ({type(action).__name__})"
        )
    index = int(action)
    if not 0 <= index < n_actions:
        raise ValueError(f"discrete action {index} is outside 0..{n_actions - 1}")
    return index


def discrete_indices(actions: Any, n_actions: int, num_envs: int) -> np.ndarray:
    """One discrete index per sub-env: an integer array of shape ``(num_envs,)`` in range (int64)."""
    batch = np.asarray(actions) if not isinstance(actions, (str, bytes)) else np.asarray([actions])
    if batch.shape != (num_envs,) or batch.dtype == np.bool_ or not np.issubdtype(batch.dtype, np.integer):
        raise ValueError(
            f"expected {num_envs} discrete actions as an integer array of shape ({num_envs},), "
            f"got {batch.dtype} of shape {batch.shape}"
        )
    if batch.size and (batch.min() < 0 or batch.max() >= n_actions):
        raise ValueError(f"discrete actions must lie in 0..{n_actions - 1}, got {batch.tolist()}")
    return batch.astype(np.int64, copy=False)
