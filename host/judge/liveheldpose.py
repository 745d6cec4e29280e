"""Which ODOM_POSE_X frames of COUNTER 0 the bus held back within one firmware life, for the
power-up tick's evidence (``host.judge.sources.SourceWatch.observe``, issue #11).

A pose that fills a hole of its sender's sequence (``host.judge.livelatestatus``: 1..7 COUNTER
steps behind the latest heard in order, none heard in order in its place) was sent before
frames already heard: its COUNTER's step breaks no life's sequence. Kobuki random 696,
``delay=0.1:150``: the log's own power-up pose heard at 0.151 s after COUNTER 1, 3..7; 690: the
pose of 0.641 s heard at 0.791 s after COUNTER 6: each was told a reboot with the summary after
it. Unless the frames heard in order since the hole began with a break themselves: a new
firmware whose power-up tick the bus held back (kobuki random 692, ``reboot=0.5,delay=0.1:150``:
its COUNTER 1 came 20 ms after the old firmware's 12, its COUNTER 0 and boot summary 150 ms
late): that hole is the new life's, and the held pose of COUNTER 0 still tells it.
"""

from __future__ import annotations

from odocan.host.judge.bootticks import sooner_than_one_life
from odocan.host.judge.livelatestatus import StatusOrder
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK


class PoseOrder:
    """ODOM_POSE_X frames (CRC holding, any sequence, bus order): ``StatusOrder``'s held-back
    rule, and whether each frame heard in order broke the sequence (came sooner than one life
    could count on to its COUNTER from the one heard in order before it)."""

    order: StatusOrder
    top: int  # the latest in-order frame's COUNTER (-1: none yet)
    top_s: float  # its bus time
    broke: dict[int, bool]  # per COUNTER, whether the latest in-order frame of it broke

    def __init__(self) -> None:
        self.order = StatusOrder()
        self.top = -1
        self.top_s = 0.0
        self.broke = {}

    def hear(self, counter: int, t_s: float) -> bool:
        """One pose of E2E ``counter`` heard at bus time ``t_s``: whether it was held back
        within a sequence unbroken since the hole it fills (no power-up tick's evidence)."""
        if not self.order.hear(counter):
            self.broke[counter] = (self.top >= 0 and counter != self.top
                                   and sooner_than_one_life(counter, t_s, (self.top_s, self.top)))
            self.top, self.top_s = counter, t_s
            return False
        ahead = [((c - counter) & ENC_COUNTER_MASK, c) for c in self.order.recent]
        after = min(ahead)[1] if ahead else -1  # the first heard in order past the hole
        return not self.broke.get(after, False)
