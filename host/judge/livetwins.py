"""The live judge's twin rule (``host.judge.tracking``): ``samples.twinned_encoder_frames``
applied frame by frame, in O(1) memory.

A WHEEL_ENCODERS frame E2E refused with its CRC right (REPEATED or WRONG_SEQUENCE) that carries
the COUNTER of the latest accepted one, different counts, and comes less than half a COUNTER
cycle (8 periods) after it is that accepted frame's *twin*: a forgery that passed Profile 2's
1-in-256 CRC, or a second sender's frame. The firmware may have taken either (a full mailbox
drops frames the bus carries), so a pose naming that frame is left out, as ``analyze`` leaves
it out (``samples.match_encoder``), never guessed.

The live judge decides a pose half when it settles (half a cycle after it is heard, or at the
next half of its message). A twin heard later than that is not known then; it cannot matter:
the firmware can only have taken a frame that reached it before it sent the pose, so a pose
whose named frame has no twin on the bus before the pose was made from that frame (``analyze``,
which knows the whole log, leaves such a pose out too; the live judge keeps it, and it agrees).

Each twin's detour (``host.judge.twins``) is allowed from its frame on (``resolve``, into the
loss allowance's spans), weighing at most ``TWIN_CAP`` distinct twins of one frame (each costs
its steps from every prev choice: a forger of many CRC-right twins must not stall the judge;
``analyze`` weighs them all, so past the cap the live allowance may be the smaller).
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any

from odocan.host.judge.livewindow import CYCLE_S
from odocan.host.judge.reference import Geometry
from odocan.host.judge.twins import Counts, twin_detour_m
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

if TYPE_CHECKING:
    from odocan.host.judge.livefill import LiveFill

TWIN_SLOTS = 64  # recent encoder frames whose twin is remembered (a ring by seq)
TWIN_GAP_S = 8 * CYCLE_S  # 8 periods on, the same COUNTER is the sender's next cycle
TWIN_CAP = 16  # distinct twins per frame weighed in its detour (each costs prevs x 2 steps)
CRC_RIGHT_REFUSED = frozenset({"repeated", "wrong_sequence"})  # E2EMonitor.check's statuses


class TwinWatch:
    """Which of the latest ``TWIN_SLOTS`` accepted encoder frames (by seq) have a twin.

    A ring of seq numbers, one slot per seq modulo ``TWIN_SLOTS``: no allocation per frame.
    """

    def __init__(self, accepted: deque[tuple[float, ...]]) -> None:
        """``accepted``: the latest accepted encoder frames' rows (seq, pos, COUNTER, bus time
        s, left, right, ...: ``livewindow.ENC_COLUMNS``, the live judge's window's rows), read
        only."""
        self._accepted = accepted
        self._ring = [-1] * TWIN_SLOTS
        self.found = 0  # twins heard so far
        self._counts: dict[int, list[Counts]] = {}  # the twins' counts by seq (the latest)
        self._pending: list[int] = []  # twinned seqs whose detour waits for the next frame

    def refused(self, counter: int, left: int, right: int, t_s: float) -> None:
        """A WHEEL_ENCODERS frame refused with its CRC right (raw COUNTER, 24-bit counts, bus
        time s): a twin of the latest accepted one, or not. Runs per refused frame: no
        allocation."""
        if not self._accepted:
            return
        seq, _, latest_counter, latest_t_s, latest_left, latest_right = self._accepted[-1][:6]
        if counter != latest_counter or (left == latest_left and right == latest_right):
            return  # another COUNTER, or an exact repetition (no twin)
        if t_s - latest_t_s >= TWIN_GAP_S:
            return
        self._ring[int(seq) % TWIN_SLOTS] = int(seq)
        self.found += 1
        twins = self._counts.setdefault(int(seq), [])
        if len(twins) < TWIN_CAP and (left, right) not in twins:
            twins.append((left, right))
        if not self._pending or self._pending[-1] != int(seq):
            self._pending.append(int(seq))
            if len(self._pending) > TWIN_SLOTS:  # no reference to resolve them: the oldest go
                self._counts.pop(self._pending.pop(0), None)

    def resolve(self, geometry: Geometry, bits: int, integrator: str | None
                ) -> list[tuple[int, float]]:
        """(seq, ``twins.twin_detour_m``) of the twinned frames whose next accepted frame has
        come since the last call (the whole log's ``twins.twin_spans``, the window's frames
        numbered by seq one apart); twins whose frames left the window are dropped."""
        rows = self._accepted
        if not self._pending or not rows or integrator is None:
            return []
        latest = int(rows[-1][0])
        spans = []
        waiting = [seq for seq in self._pending if seq >= latest]
        for seq in (s for s in self._pending if s < latest):
            i = len(rows) - 1 - (latest - seq)  # its row: the window's seqs are consecutive
            if i < 1:
                continue
            counts = [(int(rows[j][4]), int(rows[j][5])) for j in (i - 1, i, i + 1)]
            prevs = [counts[0], *self._counts.get(seq - 1, [])]
            periods = (max(1, int(rows[i][2] - rows[i - 1][2]) & ENC_COUNTER_MASK),  # COUNTER steps
                       max(1, int(rows[i + 1][2] - rows[i][2]) & ENC_COUNTER_MASK))
            spans.append((seq, twin_detour_m(prevs, counts[1], self._counts[seq], counts[2],
                                             periods, geometry, bits, integrator)))
        self._pending = waiting
        for old in [s for s in self._counts if s < latest - TWIN_SLOTS]:
            del self._counts[old]
        return spans

    def twinned(self, seq: int) -> bool:
        """Whether accepted encoder frame ``seq`` has a twin heard so far."""
        return seq >= 0 and self._ring[seq % TWIN_SLOTS] == seq


def refused_encoders(twins: TwinWatch, signals: Any, t_s: float,
                     fill: LiveFill | None = None) -> None:
    """A WHEEL_ENCODERS frame E2E refused with its CRC right, decoded (``signals``: COUNTER,
    LEFT_COUNT, RIGHT_COUNT raw: a mapping, as cantools decodes it), heard at bus time
    ``t_s``: to ``twins``, and to ``fill`` (a gap's frame, ``livefill``)."""
    frame = (int(signals["COUNTER"]), int(signals["LEFT_COUNT"]), int(signals["RIGHT_COUNT"]))
    twins.refused(*frame, t_s)
    if fill is not None:
        fill.refused(*frame, t_s)
