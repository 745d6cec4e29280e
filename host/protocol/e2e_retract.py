"""Encoder frames the host took on a capture's stamps but the firmware's poses prove it refused,
taken back (issue #11 point 5/6, rule 3: a PASS never hides a wrong pose), for
``host.protocol.e2e_evidence.settle``.

After a late frame, the firmware's E2E window (Profile 2, one period a tick, init 0) trails the
sender's COUNTER by one period for up to 15 periods: it refuses the frames on time until the
COUNTER comes round (a lock-out). On a capture whose stamps are each up to 3 ms late
(``tests/test_capture_jitter``) a second frame that looks late by more than the receive lag
adds a period to the host's window (``e2e_periods.receive_periods``: a late second frame is
read as such), so the host takes a lock-out's frame the firmware refused; its model's last
COUNTER is then not the firmware's, and every later frame of the lock-out is judged against the
wrong one. On pmir, seed 3, ``delay=0.1:15``, jitter seed 0 the host took 464 encoder frames
where the firmware took 347 (137 it refused); a firmware adding 1 mm of X after each lock-out
PASSed ``analyze``: its poses matched none of the host's frames and the hold's allowance there
(2 x merge over 58 frames, the test's former xfail) was 17.5 mm. With the evidence followed the
host takes 372, every one the firmware took and 25 more: at a lock-out's end, 1..4 frames before
the firmware takes one again, which no pose names (a short hold: its allowance is small).

The firmware's poses settle it (``e2e_evidence.pose_evidence``: each proof is a frame the pose
names, the one frame of that COUNTER since the previous send, or a frame on the bus between the
named one and the previous send). Where the evidence names a frame taken that the host's
windows all refuse, the host's last frame was not the firmware's: ``firmware_last`` finds,
among the frames the host took since the last one the evidence proves, the latest that the
firmware could have taken last (the proven frame within its window from it, every frame
between refusable, none proven taken), and the host's frames after it are refused as the
firmware refused them.
"""

from __future__ import annotations

from collections.abc import Sequence

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

COUNTER_MASK = ENC_COUNTER_MASK  # 0x0F
MAX_WINDOW = ENC_COUNTER_MASK  # 15
SEARCH_FRAMES = ENC_COUNTER_LAP  # the firmware's window never reaches a lap: no last further back


def firmware_last(j: int, taken: Sequence[int], counters: Sequence[int], ok: Sequence[bool],
                  cums: tuple[Sequence[int], Sequence[int]], max_delta_init: int,
                  proven: frozenset[int]) -> int | None:
    """The place in ``taken`` (the frames the host took, oldest first) of the frame the firmware
    took last before frame ``j``, which the evidence proves taken (module docstring); None when
    no frame fits (the host's state is then kept). ``cums``: the wide and narrow readings'
    receive periods summed from the first frame (the wide bounds ``j``'s window, the narrow
    each refused frame's); ``proven``: the frames the evidence proves taken."""
    wide_cum, narrow_cum = cums
    for place in range(len(taken) - 1, max(len(taken) - SEARCH_FRAMES, 0) - 1, -1):
        p = taken[place]
        delta = (counters[j] - counters[p]) & COUNTER_MASK
        window = min(max_delta_init + wide_cum[j] - wide_cum[p], MAX_WINDOW)
        if 0 < delta <= window and _refusable(p, j, counters, ok, narrow_cum, max_delta_init):
            return place
        if p in proven:
            return None  # the firmware took it: its last is not further back
    return None


def _refusable(p: int, j: int, counters: Sequence[int], ok: Sequence[bool],
               narrow_cum: Sequence[int], max_delta_init: int) -> bool:
    """Whether a firmware whose last frame was ``p`` refused every frame between ``p`` and
    ``j``: each a repeat of ``p``'s COUNTER or beyond ``p``'s window by the narrow reading (the
    fewest periods the stamps allow), never the next COUNTER (always taken)."""
    for q in range(p + 1, j):
        if not ok[q]:
            continue
        delta = (counters[q] - counters[p]) & COUNTER_MASK
        window = min(max_delta_init + narrow_cum[q] - narrow_cum[p], MAX_WINDOW)
        if delta == 1 or 0 < delta <= window:
            return False
    return True
