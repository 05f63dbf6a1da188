"""Per-environment random streams that draw an episode's randomness up front, exactly.

The original release draws the start hour at reset and one normal(0, 0.004) price shock per
step from the env's generator. Drawing the whole episode's shocks at reset (one call) gives
the same numbers and, after a complete episode, the same generator state. When an episode is
cut short, :meth:`EpisodeStream.truncate_last` rewinds the generator to where one-at-a-time
drawing would have left it: it restores a checkpoint and replays the logged draws.

The start hour is drawn as ``rng.integers(0, n, dtype=np.int32)``, which consumes the same
random bits and gives the same index as the original's ``rng.choice(starts)``.
"""

from __future__ import annotations

import numpy as np

PRICE_NOISE_STD = 0.004
CHECKPOINT_EVERY = 64  # episodes between generator-state snapshots (bounds the replay cost)
_FIELD = 20
_FIELD_MASK = (1 << _FIELD) - 1
_KIND_MASK = (1 << 2 * _FIELD) - 1


def _entry(repeat: int, n_starts: int, n_noise: int) -> int:
    # One plain int per run of identical episodes (cheap for the garbage collector).
    return repeat << 2 * _FIELD | n_starts << _FIELD | n_noise


def _unpack(entry: int) -> tuple[int, int, int]:
    return entry >> 2 * _FIELD, (entry >> _FIELD) & _FIELD_MASK, entry & _FIELD_MASK


def draw_start(rng: np.random.Generator, n_starts: int) -> int:
    return int(rng.integers(0, n_starts, dtype=np.int32))


class EpisodeStream:
    """Start-hour and price-noise draws of one environment's generator.

    ``episodes`` counts the episodes logged since the last checkpoint.
    """

    __slots__ = ("rng", "_checkpoint", "_log", "episodes")

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.checkpoint()

    def checkpoint(self) -> None:
        self._checkpoint = self.rng.bit_generator.state
        self._log: list[int] = []
        self.episodes = 0

    def record(self, n_starts: int, n_noise: int, repeat: int = 1) -> None:
        """Log ``repeat`` episodes that drew a start among ``n_starts`` (0: none) and
        ``n_noise`` shocks (draws made by the caller)."""
        if repeat <= 0:
            return
        if n_starts > _FIELD_MASK or n_noise > _FIELD_MASK:
            raise ValueError("episode too long or too many start hours for the draw log")
        log = self._log
        kind = n_starts << _FIELD | n_noise
        if log and log[-1] & _KIND_MASK == kind:
            log[-1] += repeat << 2 * _FIELD
        else:
            log.append(_entry(repeat, n_starts, n_noise))
        self.episodes += repeat

    def begin(self, n_starts: int, noise_out: np.ndarray) -> int:
        """Draw a start index in [0, n_starts) (none if ``n_starts`` is 0, returning -1) and
        fill ``noise_out`` with standard normals; the caller scales them by 0.004."""
        if self.episodes >= CHECKPOINT_EVERY:
            self.checkpoint()
        index = draw_start(self.rng, n_starts) if n_starts else -1
        self.rng.standard_normal(out=noise_out)
        self.record(n_starts, noise_out.shape[0])
        return index

    def truncate_last(self, consumed: int) -> None:
        """Declare that the last episode used only ``consumed`` of its noise draws."""
        if not self._log:
            return
        repeat, n_starts, n_noise = _unpack(self._log[-1])
        if consumed >= n_noise:
            return
        if repeat > 1:
            self._log[-1] = _entry(repeat - 1, n_starts, n_noise)
            self._log.append(_entry(1, n_starts, consumed))
        else:
            self._log[-1] = _entry(1, n_starts, consumed)
        rng = self.rng
        rng.bit_generator.state = self._checkpoint
        for entry in self._log:
            repeat, n_starts, n_noise = _unpack(entry)
            for _ in range(repeat):
                if n_starts:
                    rng.integers(0, n_starts, dtype=np.int32)
                if n_noise:
                    rng.standard_normal(n_noise)
