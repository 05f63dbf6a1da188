"""Action decoding, sanitising and encoding (SPEC §3 "Action decoding", §5, §7).

Policies act in normalised space u ∈ [0, 1]^3. Decoding maps u to market units in float32
(α = 0.05 + 0.60 u₁, ℓ = 0.20 + 0.75 u₂, b = 0.20 u₃), then sanitises in float64: clip each
component to its range and, if α + ℓ > 0.98, scale both by 0.98 / (α + ℓ); the executed
action is float32. Encoding is the inverse for policies that think in market units.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import MarketConfig
from .ops import BATCH, SCALAR

_F32 = np.float32


@dataclass(frozen=True)
class ActionCodec:
    """Ranges of (reward ratio α, liquidity ratio ℓ, burn rate b), all dimensionless.

    ``lo32``/``width32`` are the float32 decoding constants; ``lo``/``hi`` the float64
    sanitising bounds.
    """

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    lo32: tuple[float, float, float]
    width32: tuple[float, float, float]
    max_total_allocation: float

    @classmethod
    def from_config(cls, market: MarketConfig) -> "ActionCodec":
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

    # --- generic (ops-parameterised) core -------------------------------------------------
    def sanitize_with(self, ops: Any, alpha: Any, ell: Any, burn: Any) -> tuple[Any, Any, Any]:
        """Clip to ranges and enforce α + ℓ <= max_total_allocation; returns float32 values."""
        alpha = ops.clip(alpha, self.lo[0], self.hi[0])
        ell = ops.clip(ell, self.lo[1], self.hi[1])
        burn = ops.clip(burn, self.lo[2], self.hi[2])
        total = alpha + ell
        over = total > self.max_total_allocation
        scale = self.max_total_allocation / ops.maximum(total, 1e-300)
        alpha = ops.where(over, alpha * scale, alpha)
        ell = ops.where(over, ell * scale, ell)
        return ops.f32x3(alpha, ell, burn)

    def decode_with(self, ops: Any, u0: Any, u1: Any, u2: Any) -> tuple[Any, Any, Any]:
        """Decode float32-valued normalised components (NaN -> 0, ±inf clipped)."""
        u0 = ops.clip(ops.nan_to_zero(u0), 0.0, 1.0)
        u1 = ops.clip(ops.nan_to_zero(u1), 0.0, 1.0)
        u2 = ops.clip(ops.nan_to_zero(u2), 0.0, 1.0)
        w0, w1, w2 = self.width32
        p0, p1, p2 = ops.f32x3(u0 * w0, u1 * w1, u2 * w2)
        alpha, ell, burn = ops.f32x3(self.lo32[0] + p0, self.lo32[1] + p1, p2)
        return self.sanitize_with(ops, alpha, ell, burn)

    # --- single actions ---------------------------------------------------------------------
    def decode(self, action: Any) -> tuple[float, float, float]:
        """Decode one continuous action (array-like of 3) to executed (α, ℓ, b)."""
        u = action if isinstance(action, np.ndarray) and action.dtype == _F32 else np.asarray(action, dtype=_F32)
        if u.shape != (3,):
            u = u.reshape(-1)
            if u.shape != (3,):
                raise ValueError(f"a continuous action has 3 components, got shape {np.shape(action)}")
        u0, u1, u2 = u.tolist()
        return self.decode_with(SCALAR, u0, u1, u2)

    def sanitize(self, alpha: float, ell: float, burn: float) -> tuple[float, float, float]:
        """Sanitise an action in market units (float32 inputs are promoted); float32 result."""
        return self.sanitize_with(SCALAR, float(alpha), float(ell), float(burn))

    def encode(self, alpha: float, ell: float, burn: float) -> np.ndarray:
        """Market-unit target -> normalised float32 action (sanitised first, then clipped)."""
        a, l, b = self.sanitize(alpha, ell, burn)
        u = SCALAR.f32x3(a - self.lo32[0], l - self.lo32[1], b)
        u = SCALAR.f32x3(u[0] / self.width32[0], u[1] / self.width32[1], u[2] / self.width32[2])
        return np.clip(np.array(u, dtype=_F32), 0.0, 1.0)

    # --- batches ----------------------------------------------------------------------------
    def decode_batch(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Decode an (N, 3) batch; returns float64 arrays holding float32 values."""
        u = np.asarray(actions, dtype=_F32)
        if u.ndim != 2 or u.shape[1] != 3:
            raise ValueError(f"a batch of continuous actions has shape (N, 3), got {u.shape}")
        u64 = u.astype(np.float64)
        return self.decode_with(BATCH, u64[:, 0], u64[:, 1], u64[:, 2])

    def discrete_grid(self, levels: int) -> np.ndarray:
        """The normalised grid {0, 1/(k-1), ..., 1}^3 in itertools.product order, float32."""
        values = np.linspace(0.0, 1.0, int(levels), dtype=_F32)
        return np.array(list(itertools.product(values, values, values)), dtype=_F32)

    def discrete_table(self, levels: int) -> list[tuple[float, float, float]]:
        """Executed (α, ℓ, b) of every grid point."""
        return [self.decode(point) for point in self.discrete_grid(levels)]


def action_jitter_f32(ops: Any, a: tuple, prev: tuple) -> Any:
    """|a - a_prev|_1 in float32 (numpy's float32 order: left to right)."""
    d0, d1, d2 = ops.f32x3(abs(a[0] - prev[0]), abs(a[1] - prev[1]), abs(a[2] - prev[2]))
    return ops.f32(ops.f32(d0 + d1) + d2)
