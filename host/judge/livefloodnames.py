"""The live judge's names a sender's flood makes ambiguous (``host.judge.floodnames``, the whole
log's rule): a pose made in the flood names its frame by the 4-bit ENC_COUNTER, and the frames
a COUNTER lap, two, ... before the latest of that COUNTER came in the same flood. Its HEADING
picks the candidate, from the last pose named without doubt, only when exactly one matches;
every frame sent with it (its Y half, the twist: the same ENC_COUNTER and name, less than a
cycle apart) follows (``follow``, in ``PoseTracker.named``).

The frames are kept by the sender's sequence (COUNTER steps, widened by the bus times as
``samples.sender_seq``) with their counts unwrapped, ``FLOOD_FRAMES`` of them (10 s at 100 Hz):
a candidate older than that is not among them, and then no other candidate's heading matches
(the plain rule's name stands). A frame resolved beyond the live window (``ENC_WINDOW``: its
reference no longer kept) leaves the pose unjudged, and the end verdict UNJUDGED rather than a
PASS (``beyond_why``, with ``livereprime.unbounded_why``)."""

from __future__ import annotations

import math
from collections import deque

from odocan.host.judge.floodnames import HALF_LAP, pick
from odocan.host.judge.livelapfirst import first_lap
from odocan.host.judge.livewindow import ENC_WINDOW
from odocan.host.judge.reference import Geometry
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

FLOOD_FRAMES = 1024
CYCLE_S = busfacts.ENC_CYCLE_S
# one frame kept: the tracker's seq, bus time s, cumulative left and right counts
Kept = tuple[int, float, int, int]


class LiveFloodNames:
    """The frames kept, the anchor (the last ODOM_POSE_X named without doubt: its frame's
    sender sequence, HEADING raw) and the latest rename (plain seq, resolved seq, ENC_COUNTER,
    bus time s)."""

    def __init__(self) -> None:
        self._kept: dict[int, Kept] = {}
        self._order: deque[int] = deque()
        # the latest frame: sender seq, COUNTER, bus time s, raw left, right, cumulative ones
        self._last: tuple[int, int, float, int, int, int, int] | None = None
        self.anchor: tuple[int, int] | None = None
        self.renamed: tuple[int, int, int, float] | None = None
        self.beyond = 0  # renames to a frame beyond the live window (``beyond_why``)

    def frame(self, seq: int, counter: int, counts: tuple[int, int], t_s: float,
              bits: int) -> None:
        """An accepted encoder frame (the tracker's ``seq``, raw ``counts`` wrapping at
        ``bits``) at bus time ``t_s``."""
        last = self._last
        if last is None:
            sseq, left, right = 0, counts[0], counts[1]
        else:
            step = (counter - last[1]) & ENC_COUNTER_MASK
            laps = math.floor(((t_s - last[2]) / CYCLE_S - step) / ENC_COUNTER_LAP + 0.5)
            laps = laps if laps > 0 else 0  # ``max(0, laps)`` written out (per encoder frame)
            sseq = last[0] + step + ENC_COUNTER_LAP * laps
            half, wrap = 1 << (bits - 1), 1 << bits  # ``_wrapped`` in line (per encoder frame)
            left = last[5] + ((counts[0] - last[3] + half) % wrap) - half
            right = last[6] + ((counts[1] - last[4] + half) % wrap) - half
        self._last = (sseq, counter, t_s, counts[0], counts[1], left, right)
        self._kept[sseq] = (seq, t_s, left, right)
        self._order.append(sseq)
        if len(self._order) > FLOOD_FRAMES:
            self._kept.pop(self._order.popleft(), None)

    def pose_x(self, enc_counter: int, heading_raw: int, t_s: float, geometry: Geometry) -> None:
        """An ODOM_POSE_X heard: the anchor when its name is without doubt, else a rename when
        its HEADING matches exactly one candidate other than the plain rule's."""
        last = self._last
        if last is None or t_s - last[2] >= HALF_LAP * CYCLE_S:
            return
        step = ((enc_counter - last[1] + HALF_LAP) & ENC_COUNTER_MASK) - HALF_LAP
        if step > 0 or last[0] + step not in self._kept:
            return
        if self.anchor is None and (lap := first_lap(self._kept, last[0] + step, heading_raw,
                                                     geometry)) is not None and (
                self._kept[last[0]][0] - lap[1] < ENC_WINDOW):  # livelapfirst
            self.anchor = (lap[0], heading_raw)
            self.renamed = (self._kept[last[0] + step][0], lap[1], enc_counter, t_s)
            return
        cands = self._candidates(last[0] + step)
        if len(cands) == 1:
            self.anchor = (cands[0], heading_raw)
            return
        if self.anchor is None or self.anchor[0] not in self._kept:
            return
        a = self._kept[self.anchor[0]]
        found = pick(geometry, (a[2], a[3], self.anchor[1]),
                     [(self._kept[c][2], self._kept[c][3]) for c in cands], heading_raw)
        if found:  # (0: the plain rule's own)
            resolved = self._kept[cands[found]][0]
            self.renamed = (self._kept[cands[0]][0], resolved, enc_counter, t_s)
            if self._kept[last[0]][0] - resolved >= ENC_WINDOW:
                self.beyond += 1  # its reference no longer kept: not judged (``beyond_why``)

    def _candidates(self, sseq: int) -> list[int]:
        """``floodnames.candidates`` on the frames kept, after the anchor's."""
        after = self.anchor[0] if self.anchor is not None else -1
        out = [sseq]
        while (sseq - ENC_COUNTER_LAP in self._kept and sseq - ENC_COUNTER_LAP > after
               and self._kept[sseq][1] - self._kept[sseq - ENC_COUNTER_LAP][1]
               < HALF_LAP * CYCLE_S):
            sseq -= ENC_COUNTER_LAP
            out.append(sseq)
        return out

    def follow(self, seq: int, rows: deque[tuple[float, ...]], pos: int) -> int:
        """``seq`` (the plain name of the frame at ``pos``, one of ``rows``: pos, ENC_COUNTER,
        COUNTER, bus time s) renamed when it is the latest rename's plain name, with its
        ENC_COUNTER, less than a cycle from it."""
        renamed = self.renamed
        if renamed is None or seq != renamed[0]:
            return seq
        for row in reversed(rows):
            if row[0] == pos:
                if row[1] == renamed[2] and abs(row[3] - renamed[3]) < CYCLE_S:
                    return renamed[1]
                break
        return seq


def beyond_why(floods: LiveFloodNames) -> str | None:
    """Why the end verdict cannot be a PASS (UNJUDGED): a pose made in a flood named a frame
    more than ``ENC_WINDOW`` frames before the latest (a pause of 5 s or more), whose
    reference the live judge no longer keeps; None else (``analyze`` judges it)."""
    if not floods.beyond:
        return None
    return (f"{floods.beyond} pose{'' if floods.beyond == 1 else 's'} made in a sender's flood "
            f"named a frame more than {ENC_WINDOW} encoder frames before the latest, beyond the "
            "live window: not judged (analyze judges it)")
