"""A babbling node: frames at a Poisson rate, sent by another node on the same wire.

``babble=RATE[:ID[:T:DUR]]`` of a ``FaultSpec``, at RATE frames per second of the sender's time:
without ID, random frames (11/29-bit IDs, DLC 0-8, random payloads, 10 % error frames, 10 %
remote frames); with ID, a stuck node's data frames of 8 random bytes on that one identifier
(29-bit above 0x7FF). The babbler wakes up with the first frame its host controller sends (or at
T, if that is later) and keeps its own schedule; with T:DUR it falls silent at T + DUR.
"""

from __future__ import annotations

import math
import random

import can

from odocan.sim.faultspec import BusOff

_BABBLE_ERROR_FRAMES = 0.1  # share of the babble that is error frames
_BABBLE_REMOTE_FRAMES = 0.1  # ... and remote frames (the rest: data frames)


class Babbler:
    """The babbling node's schedule and frames.

    Args:
        rate_per_s: frames per second (0: silent).
        rng: its own random stream (intervals and frames).
        can_id: the one identifier of a stuck node (None: random frames).
        window: when it babbles (None: from the first frame seen, for ever).
    """

    def __init__(
        self,
        rate_per_s: float,
        rng: random.Random,
        *,
        can_id: int | None = None,
        window: BusOff | None = None,
    ) -> None:
        self.rate_per_s = rate_per_s
        self.can_id = can_id
        self._rng = rng
        self._window = window
        self._end_s = math.inf if window is None else window.at_s + window.duration_s
        self._next_s: float | None = None

    def next_s(self, now_s: float) -> float:
        """The time of the next babble frame (s); ``inf`` when silent."""
        if self.rate_per_s <= 0.0:
            return math.inf
        if self._next_s is None:  # the babbler wakes up with the first frame seen (or at T)
            start_s = now_s if self._window is None else max(now_s, self._window.at_s)
            self._next_s = start_s + self._rng.expovariate(self.rate_per_s)
        return self._next_s if self._next_s < self._end_s else math.inf

    def frame(self, t_s: float) -> can.Message:
        """The frame due at ``t_s`` (s); schedules the next one."""
        if self.can_id is None:
            msg = _random_frame(self._rng, t_s)
        else:
            msg = can.Message(
                timestamp=t_s,
                arbitration_id=self.can_id,
                is_extended_id=self.can_id > 0x7FF,
                data=self._rng.randbytes(8),
            )
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
