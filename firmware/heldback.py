"""A WHEEL_ENCODERS frame the bus held back behind newer ones is refused, not integrated backward.

The E2E check knows a frame only by its 4-bit COUNTER: after a silence (a bus-off, a stall: the
window widens to 15) a frame sent BEFORE the last one integrated passes it as OKSOMELOST, and the
plausibility bound, widened by the silence's periods, passes its step back. Integrated, it is a
step back in time: the counts are absolute, so the pose nets out over the step back and the step
forward again, but DISTANCE (the sum of |dS|) counts both, a path the robot never drove (issue
#11: kobuki circle 652, 9 s, ``busoff=3.1:0.3,stall=5.5:0.2,delay=0.3:55``: COUNTER 3, sampled
before 5, let out after the bus-off: steps of +156, -104 and +52 counts on the left wheel where it
turned +104 from 2 to 4, the wheels' counts and the truth rising throughout; after the stall,
COUNTER 0 after 3, -156; DISTANCE 1.99 mm beyond the judge's tolerance, 50.0 mm above the
wheels' path at the end: ``tests/test_distance_late.py``).

Such a frame is told before its E2E check (its CRC right) by what the firmware integrated
already: its COUNTER is one a recent step skipped (an OKSOMELOST advance of n from COUNTER
``first``: ``first`` + k, 0 < k < n) and each wheel's counts lie within that step (between its two
frames' counts): it was sampled inside a step taken already. When the plausibility bound (or the
doubt, ``sampledoubt``) would pass it as a step back, it is dropped as if the bus had lost it:
the E2E check never sees it (ENC_E2E_OK does not count it, the E2E state does not move), nothing
is integrated, and the next frame steps from the last integrated one (the counts are absolute:
the pose is the same). One the bound refuses goes on to E2E and ``_on_implausible`` as before.
``first`` + k is told until the frames accepted since the step come round to it (16 - n + k
COUNTER advances): a frame the bus held through a silence, when no frame was accepted, is still
told. A genuine frame is dropped so only when the robot came back inside the step's counts
(standing still, or reversing onto it) with a COUNTER the step skipped: nothing is lost but its
own step, merged into the next (the pose exact, DISTANCE as a lost frame leaves it).

C: the ``held_*`` arrays of ``struct odom_ecu`` (firmware/c/ecu.c ``held_note``, ``held_back``).
"""

from __future__ import annotations

from odocan.firmware.e2e import COUNTER_MASK
from odocan.firmware.fixmath import U32_MAX

HELD_STEPS = 8  # steps remembered: each skips a COUNTER, so a COUNTER cycle holds at most 8
COUNTER_VALUES = 16

Counts = tuple[int, int]  # (left, right) counter values


class HeldBack:
    """The recent steps that skipped COUNTERs (C: fixed arrays of ``HELD_STEPS``)."""

    __slots__ = ("_ends", "_first", "_from", "_span", "_to", "frames", "next_slot", "refused",
                 "used")

    def __init__(self) -> None:
        self._first = [0] * HELD_STEPS  # u8: the step's first frame's COUNTER
        self._span = [0] * HELD_STEPS  # u8: its COUNTER advance, 2..16 (0: slot unused)
        self._from: list[Counts] = [(0, 0)] * HELD_STEPS  # u32: counts of its first frame
        self._to: list[Counts] = [(0, 0)] * HELD_STEPS  # u32: counts of its last frame
        self._ends = [0] * HELD_STEPS  # u32: ``frames`` when it was taken
        self.frames = 0  # u32, wrapping: the COUNTER advances of the frames accepted
        self.next_slot = 0  # u8: the slot the next step takes (a ring)
        self.used = 0  # u8: slots in use
        self.refused = 0  # u32, wrapping: frames refused as held back (the caller counts)

    def clear(self) -> None:
        """Forget every step (a re-prime: counts before it are no base for a frame after it)."""
        self.used = 0
        for slot in range(HELD_STEPS):
            self._span[slot] = 0

    def note(self, first: int | None, last: int, counts_first: Counts | None,
             counts_last: Counts) -> None:
        """A step integrated from the frame of COUNTER ``first`` (``counts_first``) to the one of
        ``last`` (``counts_last``): remembered when it skipped a COUNTER (None: no frame before,
        no step; C: ``enc_prev_counter`` -1 or ``counts_prev_valid`` false)."""
        if first is None or counts_first is None:
            return
        span = ((last - first) & COUNTER_MASK) or COUNTER_VALUES  # u8: 1..16
        self.frames = (self.frames + span) & U32_MAX
        if span < 2:
            return
        slot = self.next_slot
        self._first[slot], self._span[slot] = first, span
        self._from[slot], self._to[slot] = counts_first, counts_last
        self._ends[slot] = self.frames
        self.next_slot = (slot + 1) & (HELD_STEPS - 1)
        if self.used < HELD_STEPS:
            self.used += 1

    def held_back(self, counter: int, counts: Counts, half: int) -> bool:
        """True when the frame (``counter``, ``counts``) was sampled inside a remembered step:
        a COUNTER it skipped, each wheel's counts within it (read wrap-safe in the counters'
        width, ``half`` its half range)."""
        if self.used == 0:
            return False
        for slot in range(HELD_STEPS):
            span = self._span[slot]
            skipped = (counter - self._first[slot]) & COUNTER_MASK
            if span == 0 or skipped == 0 or skipped >= span:
                continue
            since = (self.frames - self._ends[slot]) & U32_MAX  # frames accepted after it
            if since >= COUNTER_VALUES - span + skipped:  # its COUNTER came round since
                continue
            if _within(self._from[slot], self._to[slot], counts, half):
                return True
        return False


def _within(first: Counts, last: Counts, counts: Counts, half: int) -> bool:
    """Each wheel's ``counts`` between ``first``'s and ``last``'s (ends included), the deltas
    read signed in the counters' width (``half``: half its range)."""
    mask = half + half - 1
    for wheel in (0, 1):
        step = ((last[wheel] - first[wheel] + half) & mask) - half
        into = ((counts[wheel] - first[wheel] + half) & mask) - half
        if not (0 <= into <= step or step <= into <= 0):
            return False
    return True
