"""Whether a pose send came after the one heard before it (``e2e_evidence.pose_evidence``'s pairs),
from its 4-bit COUNTER and, past half a COUNTER lap, from the sender's cadence.

A step of 1..7 COUNTERs is a later send (as before: a frame held back further reads ``unread``).
A step of 8..15 is ambiguous by the COUNTER alone: a send 8..15 on, or a frame held back 1..8
sends. After a silence of the whole bus (a bus-off) the firmware's first pose is always such a
step, and without it no pose after the silence proved anything until the firmware moved on: on
kobuki, seed 3, ``busoff=4:0.5,delay=0.2:30``, the ODOM_POSE_X of 4.521 .. 4.601 s all named the
encoder frame COUNTER 15 the bus-off held (heard 4.502816 s), but the host's window, a period
wider than the firmware's after that late frame, took the COUNTER 7 and 8 of 4.58 and 4.59 s
that the firmware refused, split its 243 mm merged arc in three and FAILed it 1.78 mm off the
reference. The pair (COUNTER 7 at 3.981 s, COUNTER 2 at 4.521 s) is 0.54 s = 27 send periods
apart, 11 COUNTERs on: 11 + 16 sends, on cadence, a later send.

The cadence proves it where the gap in send periods lies within ``ON_CADENCE`` of a whole number
congruent to the step, and that number is positive (a held-back frame reads a gap short of its
step, or negative).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

HALF_LAP = ENC_COUNTER_LAP // 2  # 8: COUNTER steps below it are later sends by the COUNTER alone
ON_CADENCE = 0.25  # send periods: a send heard within this of its cadence slot (1 ms jitter
# and the rig's whole-ms stamps at 20 ms sit far inside; a frame held a quarter send is no proof)


def later_send(dt_s: float, step: int, period_s: float) -> bool:
    """Whether a pose frame ``step`` COUNTERs (mod 16) and ``dt_s`` s after the one heard before
    it was sent after it (module docstring)."""
    step &= ENC_COUNTER_MASK
    if 0 < step < HALF_LAP:
        return True
    if step == 0 or not math.isfinite(dt_s):
        return False
    sends = sends_between(dt_s, step, period_s)
    return sends > 0 and abs(dt_s / period_s - sends) <= ON_CADENCE


def sends_between(dt_s: float, step: int, period_s: float) -> int:
    """The sends from one frame to one ``step`` COUNTERs (mod 16) and ``dt_s`` s after it, on
    the sender's cadence ``period_s``: the integer congruent to the step nearest the gap in
    periods (negative: a frame sent before the other)."""
    step &= ENC_COUNTER_MASK
    x = dt_s / period_s
    return step + ENC_COUNTER_LAP * math.floor((x - step + HALF_LAP) / ENC_COUNTER_LAP)


def later_sends(timestamp_s: npt.NDArray[np.float64], counter: npt.NDArray[np.int64],
                period_s: float) -> list[bool]:
    """Per pair of consecutive pose frames (bus times ``timestamp_s``, COUNTERs ``counter``):
    whether the second was sent after the first (``later_send``)."""
    stamps, counters = timestamp_s.tolist(), counter.tolist()
    return [later_send(stamps[k] - stamps[k - 1], counters[k] - counters[k - 1], period_s)
            for k in range(1, len(stamps))]
