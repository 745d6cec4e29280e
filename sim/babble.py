"""A babbling node: frames at a Poisson rate, sent by another node on the same wire.

``babble=RATE`` of a ``FaultSpec``: random frames (11/29-bit IDs, DLC 0-8, random payloads, 10 %
error frames, 10 % remote frames) at RATE frames per second of the sender's time. The babbler
wakes up with the first frame its host controller sends and then keeps its own schedule.
"""

from __future__ import annotations

import math
import random

import can

_BABBLE_ERROR_FRAMES = 0.1  # share of the babble that is error frames
_BABBLE_REMOTE_FRAMES = 0.1  # ... and remote frames (the rest: data frames)


class Babbler:
    """The babbling node's schedule and frames.

    Args:
        rate_per_s: frames per second (0: silent).
        rng: its own random stream (intervals and frames).
    """

    def __init__(self, rate_per_s: float, rng: random.Random) -> None:
        self.rate_per_s = rate_per_s
        self._rng = rng
        self._next_s: float | None = None

    def next_s(self, now_s: float) -> float:
        """The time of the next babble frame (s); ``inf`` when silent."""
        if self.rate_per_s <= 0.0:
            return math.inf
        if self._next_s is None:  # the babbler wakes up with the first frame seen
            self._next_s = now_s + self._rng.expovariate(self.rate_per_s)
        return self._next_s

    def frame(self, t_s: float) -> can.Message:
        """The frame due at ``t_s`` (s); schedules the next one."""
        msg = _random_frame(self._rng, t_s)
        self._next_s = t_s + self._rng.expovariate(self.rate_per_s)
        return msg


def _random_frame(rng: random.Random, t_s: float) -> can.Message:
    """A babbling node's frame: any ID, DLC 0-8, random bytes; some error and remote frames."""
    u = rng.random()
    extended = rng.random() < 0.5
    can_id = rng.getrandbits(29 if extended else 11)
    dlc = rng.randint(0, 8)
    if u < _BABBLE_ERROR_FRAMES:
        return can.Message(
            timestamp=t_s, arbitration_id=can_id, is_error_frame=True, data=rng.randbytes(dlc)
        )
    if u < _BABBLE_ERROR_FRAMES + _BABBLE_REMOTE_FRAMES:
        return can.Message(
            timestamp=t_s,
            arbitration_id=can_id,
            is_extended_id=extended,
            is_remote_frame=True,
            dlc=dlc,
        )
    return can.Message(
        timestamp=t_s, arbitration_id=can_id, is_extended_id=extended, data=rng.randbytes(dlc)
    )


__all__ = ["Babbler"]
