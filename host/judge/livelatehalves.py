"""The live judge's pose halves held back on the bus (issue #11: a FAIL must never blame a
correct firmware; the live half of ``host.judge.latenames``).

Under ``delay=0.5:150`` half the frames reach the bus 150 ms late: 15 encoder periods, 7.5 pose
periods. A pose half held back so long names its encoder frame by a 4-bit ENC_COUNTER that,
resolved where it is heard, lands on the frame 16 after its own, and the host's E2E takes it
whenever the late frames run in sequence among themselves. ``analyze`` names such a half where
it was sent (``latenames.sent_places``, read by ``LateScan``); the live judges (the monitor,
the bridge) paired it with the on-time other half of the frame 16 on: pmir random 6, the X of
the frame of 2.20 s with the Y of the frame of 2.04 s (37 mm apart), the reference placed onto
that mixed pose within a stall's budget, and 16.7 mm beyond the allowance once the pages
withdrew the budget (kobuki 1, 4, 7, pmir 4: 1.5 to 8.5 mm). The live judge now reads every
CRC-right frame of each pose message (its E2E check's verdict aside, as ``sent_places`` reads
them) with the same ``LateScan``, in bus order, and names a half it reads late where it was
sent (``named_sent``: by the plain rule from the latest encoder frame heard before its send, as
``match_encoder`` names a half ``sent_places`` moved), or leaves it out (unmatched) where that
frame is no longer among the latest rows, or where a later frame was compared already (the live
judge compares in frame order; ``analyze`` sorts its samples). Leaving every late half out is no
answer: where the host's E2E took only the late run (kobuki random 1 from 4.0 s), no sample was
left, and X 10 mm off from 5 s PASSed.
"""

from __future__ import annotations

import math
from collections import deque

from odocan.host.judge.latenames import LateScan
from odocan.host.judge.livewindow import CYCLE_S, HALF_LAP
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, POSE_PERIOD_S

POSE_NAMES = {"ODOM_POSE_X": "x", "ODOM_POSE_Y": "y"}  # message -> the tracker's half name
# ... and the messages read late besides (``livelatetwists``: the twists, named where sent too)
LATE_NAMES = {**POSE_NAMES, "ODOM_TWIST": "twist"}


class LateHalves:
    """One ``LateScan`` per pose message (and ODOM_TWIST: ``LATE_NAMES``), fed each CRC-right
    frame once, in bus order."""

    def __init__(self, period_s: float = POSE_PERIOD_S) -> None:
        self.period_s = period_s
        self._scans = {half: LateScan(period_s) for half in LATE_NAMES.values()}
        self._last_s = {half: -math.inf for half in LATE_NAMES.values()}  # each's latest bus time

    def heard(self, half: str, t_s: float, counter: int) -> float | None:
        """A CRC-right frame of pose half ``half`` ("x", "y") at bus time ``t_s`` with E2E
        COUNTER ``counter``: when it was sent if it was held back (``LateScan``'s reading), else
        None. Bus time going back by more than a period is a new time base (a rig restarted, a
        bus replayed), not lateness: the half's scan starts afresh there (else every frame after
        reads late against the old base, and its poses are named where they were not sent)."""
        if t_s < self._last_s[half] - self.period_s:
            self._scans[half] = LateScan(self.period_s)
        self._last_s[half] = t_s
        late, sent_s = self._scans[half].feed([t_s], [counter])
        return sent_s[0] if late[0] else None

    def restart(self) -> None:
        """A new firmware's pose sequences start now (its power-up pose, ``livefreshboot``):
        each half's scan starts afresh, as ``analyze`` reads each life's frames on their own
        (else the new life's COUNTERs, behind the old life's, read late: kobuki random 696
        ``reboot=0.2:0.2,delay=0.1:150``, its X halves named 80 ms back, paired with the Y
        halves of the frames 16 before theirs)."""
        self._scans = {half: LateScan(self.period_s) for half in self._scans}

    def refused(self, name: str, t_s: float, counter: int) -> None:
        """A CRC-right frame of message ``name`` the host's E2E refused: a pose half's (or
        twist's) read in its sequence too (``sent_places`` reads every CRC-right frame)."""
        half = LATE_NAMES.get(name)
        if half is not None:
            self.heard(half, t_s, counter)


def named_sent(rows: deque[tuple[float, ...]], enc_counter: int, sent_s: float) -> int:
    """The encoder frame (the tracker's seq) a half sent at bus time ``sent_s`` names by its
    ``enc_counter``: ``match_encoder``'s plain rule from the latest frame of ``rows`` (the
    window's latest rows: seq, pos, COUNTER, bus time s, counts, sender periods since the frame
    before, ...) heard before ``sent_s``, less than half a COUNTER lap of cycles older; -1 where
    none is, where the name lies after it, or where the walk back by the sender's periods
    misses the frame (not taken) or leaves the rows kept."""
    j = -1
    while -j <= len(rows) and rows[j][3] >= sent_s:
        j -= 1
    if -j > len(rows) or sent_s - rows[j][3] >= HALF_LAP * CYCLE_S:
        return -1
    offset = ((enc_counter - int(rows[j][2]) + HALF_LAP) & ENC_COUNTER_MASK) - HALF_LAP
    back = 0
    while back < -offset and -j < len(rows):
        back += int(rows[j][6])
        j -= 1
    return int(rows[j][0]) if offset <= 0 and back == -offset else -1
