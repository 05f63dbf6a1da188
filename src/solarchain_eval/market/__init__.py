"""Pure market dynamics: action decoding, physics gate, clearing, price and reward."""

from .actions import ActionCodec, action_jitter_f32, action_jitter_f32_batch
from .dynamics import MarketHours, RewardWeights, StepOutcome, market_step
from .ops import BATCH, SCALAR, numpy_order_sum, numpy_order_variance

__all__ = [
    "ActionCodec",
    "action_jitter_f32",
    "action_jitter_f32_batch",
    "MarketHours",
    "RewardWeights",
    "StepOutcome",
    "market_step",
    "BATCH",
    "SCALAR",
    "numpy_order_sum",
    "numpy_order_variance",
]
