import numpy as np

# Positions in the observation (env.unwrapped.observation_names).
SUPPLY_GAP, RAW_VIOLATION_RATE = 5, 8


class Cautious:
    """Backs less supply in hours with many violating records; keeps liquidity when spare supply is thin.

    On the default data the raw violation rate's median is 0.08 and the supply gap's 1.36
    (docs/environment.md#typical-observation-ranges), so each rule fires in a good share of the hours.
    """

    def __init__(self, violation_threshold=0.08, gap_threshold=1.0):
        self.violation_threshold = violation_threshold
        self.gap_threshold = gap_threshold

    def act(self, observation):
        if observation[RAW_VIOLATION_RATE] > self.violation_threshold:
            return np.array([0.05, 0.5, 0.1], dtype=np.float32)  # low α + ℓ: back little invalid supply
        if observation[SUPPLY_GAP] < self.gap_threshold:
            return np.array([0.3, 0.6, 0.05], dtype=np.float32)  # thin margin: hold liquidity, damp demand
        return np.array([0.3, 0.7, 0.0], dtype=np.float32)
