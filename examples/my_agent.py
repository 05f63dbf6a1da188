import numpy as np

# Positions in the observation (env.unwrapped.observation_names).
SUPPLY_GAP, RAW_VIOLATION_RATE = 5, 8


class Cautious:
    """Pays less reward and keeps more liquidity in hours with many violating records or little spare supply."""

    def __init__(self, violation_threshold=0.1, gap_threshold=1.0):
        self.violation_threshold = violation_threshold
        self.gap_threshold = gap_threshold

    def act(self, observation):
        risky = observation[RAW_VIOLATION_RATE] > self.violation_threshold
        short = observation[SUPPLY_GAP] < self.gap_threshold
        if risky:
            return np.array([0.1, 0.9, 0.1], dtype=np.float32)
        if short:
            return np.array([0.3, 0.9, 0.05], dtype=np.float32)
        return np.array([0.5, 0.6, 0.0], dtype=np.float32)
