"""The live judge's gap fills (``host.judge.gapfill``'s rule, one frame at a time): encoder
frames the host's E2E model refused with their CRC right, placed on the sender's grid, so that a
gap of the accepted sequence whose every missing frame was heard (held back on the bus, or
refused by the firmware's E2E lock-out after it took a late frame) is bounded by the merge
errors over its known counts, not by ``gapbound``'s worst split of its travel.

The sender numbers are the live judge's own: the accepted frames' periods summed
(``liveplace.StallPlacer.on_encoders``). A refused frame is numbered as ``gapfill.late_seq``
numbers it: from the least late on the sender's grid of the last ``gapfill.ANCHOR_FRAMES``
accepted frames, the number of its COUNTER in (est - 8, est + 1]. A frame heard after the sample
that placed the reference past its gap fills it then: ``heard`` tells the placer, which places
that gap again within its fill allowance (``liveplace.StallPlacer``)."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from odocan.host.judge.gapfill import (
    ANCHOR_FRAMES,
    COUNTER_MODULO,
    MAX_LATE_PERIODS,
    Counts,
    filled,
    held,
)
from odocan.host.judge.livewindow import CYCLE_S

if TYPE_CHECKING:
    from odocan.host.judge.liveholdstep import BusOrder

KEPT_PERIODS = 512  # refused frames kept this many periods behind the latest accepted one (as
# long as ``livegapskips`` keeps the accepted ones: the pages proving a gap come 1.2 s later)


class LiveFill:
    """Refused encoder frames with their CRC right, by sender number (bounded state)."""

    def __init__(self) -> None:
        self.sender = 0  # the latest accepted frame's sender number
        self._anchors: deque[tuple[int, float, int]] = deque(maxlen=ANCHOR_FRAMES)
        self._counts: dict[int, Counts | None] = {}  # None: two frames of a number disagreed
        self._kept_from = 0  # the lowest sender number whose refused frames are all kept
        self.heard: Callable[[], None] | None = None  # told of every frame placed (liveplace)
        self.bus: BusOrder | None = None  # told of every frame refused (liveplace)

    def accepted(self, periods: int, counter: int, t_s: float) -> None:
        """An accepted frame ``periods`` after the one before it (COUNTER, bus time s)."""
        self.sender += 1 if periods < 1 else periods  # ``max(periods, 1)`` (per frame)
        self._anchors.append((self.sender, t_s, counter))
        if len(self._counts) > 2 * KEPT_PERIODS:
            oldest = self.sender - KEPT_PERIODS
            self._counts = {s: c for s, c in self._counts.items() if s > oldest}
            self._kept_from = oldest + 1

    def refused(self, counter: int, left: int, right: int, t_s: float) -> None:
        """A WHEEL_ENCODERS frame the host's E2E check refused with its CRC right."""
        if self.bus is not None:
            self.bus.heard(-1, counter, left, right, t_s)
        if not self._anchors:
            return
        seq_a, t_a, counter_a = min(self._anchors, key=lambda a: a[1] - a[0] * CYCLE_S)
        est = seq_a + math.floor((t_s - t_a) / CYCLE_S + 0.5)
        top = est + 1
        seq = top - ((top - seq_a - counter + counter_a) % COUNTER_MODULO)
        if seq <= est - MAX_LATE_PERIODS:
            return  # held back too long to be placed
        known = self._counts.get(seq, (left, right))
        self._counts[seq] = (left, right) if known == (left, right) else None
        if self.heard is not None:
            self.heard()

    def known(self, seq_before: int, periods: int) -> list[tuple[int, Counts]] | None:
        """The refused frames heard in a gap of ``periods`` after sender number
        ``seq_before`` (periods after it, counts), those unheard left out; None when two frames
        of one number disagreed (``gapfill.LateFrames.known``), or the frames of its numbers
        are no longer all kept (a frame left out must be one never heard)."""
        if seq_before + 1 < self._kept_from:
            return None
        return held(self._counts, seq_before, periods)

    def fill(self, seq_before: int, periods: int) -> list[Counts] | None:
        """The counts of the frames a gap of ``periods`` after sender number ``seq_before``
        lacks, when every one was heard refused; else None."""
        return filled(self._counts, seq_before, periods)
