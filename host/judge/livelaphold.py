"""The live judge holds the samples after a COUNTER lap the stamps alone gave, until the
evidence that numbers it as ``analyze`` numbers it is heard (issue #11, rule 3: a FAIL must
never blame a correct firmware, rule 5: a PASS must never hide a wrong pose).

A step of the encoder frames heard whose COUNTER step the bus times widen by a lap (16 periods
or more: ``samples.sender_seq``) is numbered by the whole log's judge with evidence that comes
after it:

* the 16 frames after the frame that ends it: a frame stamped 8 periods late or more, alone
  below its neighbours' level, had the lap counted before it; it belongs to the step after it
  (``senderseq.late_lone_frames``);
* the frames after it: the first of a burst is a busy bus's (no lap) unless the poses' COUNTER
  tells a hole of the log (``senderseq.pose_skips``, ``burst_laps``);
* the firmware's ODOM_STATUS pages after it: a recorder's chunk of 32 k + s periods brings the
  poses' COUNTER round, and only the count of frames the firmware took numbers it
  (``host.judge.holepages``); those pages come 0.6 s to 1.2 s after the hole.

The live judge placed its reference at the first sample after such a step with what the frames
heard so far said: a correct pmir firmware FAILed a recorder's lapped chunks (25 mm), and a
frame stamped 10 periods late before a chunk kept a phantom gap's allowance at the step before
it, where a firmware 1 LSB off PASSed. Now the on-board samples naming the step's frame or later
wait, unjudged and not yet compared (the stall rules run on them when they are, in order, as
if they came then: a hold seen across a chunk belongs to its sample, not to the one before), until
``LAP`` frames after it are heard and, when pages of the life were heard before it and the
window's numbering then takes the lap back (a busy bus's burst, the pages may overturn), until
an ENC_E2E page after it and a FRAME_TOTALS page after that one are kept
(``LiveSeen.told_after``), at most ``PAGES_WAIT_S`` of bus time (``WAIT_S`` without pages);
the end of a watch or a restart of the reference decides at once. Then the step's placement is
numbered over the window as ``analyze`` numbers it (``liveplace._confirmed``, its laps raised
by the pages: ``livepagelaps``), and the samples held are judged in order. A live verdict so
lags such a step by at most ``PAGES_WAIT_S``. Each lap holds on its own (the samples naming
frames from a later one's on wait for that one too: an earlier chunk's samples do not wait
for the pages of a later one); bounded: ``KEPT`` holds (one more ends the
oldest), their samples those of ``PAGES_WAIT_S`` at most.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.livechoice import PAGES_WAIT_S, WAIT_S
from odocan.host.judge.liveplace import window_step
from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livewindow import Columns, Half
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

Held = tuple[FramePose, Half, bool]  # a sample held: its pose, ODOM_POSE_Y half, queued

LAP = ENC_COUNTER_LAP  # the COUNTER's lap: frames after a late frame telling it (late_lone_frames)
KEPT = 8  # laps held at once (more: the oldest ends first)
AT_ONCE_S = 20e-6  # two frames closer than any frame lasts on a 1 Mbit/s bus (47 us): stamped
# when a recorder read its backlog, not when the bus carried them (a busy bus's burst is spaced)


@dataclass
class Lapped:
    """A lapped step waiting: its frame (seq), the frames heard until it may decide (seq), its
    bus time, whether pages of the life were heard before it, the bus time it ends at
    whatever was heard (s)."""

    seq: int
    until_seq: int
    t_s: float
    heard: bool
    until_s: float
    periods: int  # the stamps' numbering of the step
    stamps_kept: bool | None = None  # the window numbers it so, its frames in (None: not asked)


class LapHold:
    """The tracker's samples held after laps of the stamps (module docstring)."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        self.pending: list[Lapped] = []  # in bus order, at most ``KEPT``
        self.held: list[Held] = []  # the samples held, in the order settled
        self.until_s = math.inf  # bus time the first hold ends at, whatever was heard (s)
        self.holds_made = 0  # holds opened (a figure for tests and benches)

    def lapped(self, seq: int, t_s: float, periods: int) -> None:
        """Encoder frame ``seq`` (bus time ``t_s``) ends a step the stamps widened by a lap to
        ``periods``: the samples naming it or later wait (the oldest hold ends first when
        ``KEPT`` wait)."""
        if len(self.pending) >= KEPT:
            self._release(1)
        seen = self._tracker.placer.seen
        heard = bool(seen.keeper.totals) or bool(seen.keeper.pages)
        self.pending.append(Lapped(seq, seq + LAP, t_s, heard,
                                   t_s + (PAGES_WAIT_S if heard else WAIT_S), periods))
        self.until_s = self.pending[0].until_s
        self.holds_made += 1

    def heard(self) -> None:
        """An encoder frame or a FRAME_TOTALS page heard: the holds whose evidence is in end."""
        ready = 0
        for hold in self.pending:
            if self._tracker.enc_seq < hold.until_seq or not self._told(hold):
                break
            ready += 1
        self._release(ready)

    def _told(self, hold: Lapped) -> bool:
        """Whether the pages told what they may of ``hold``'s step (its frames are in): none of
        the life heard, the pages after it kept, or no page needed: the window numbers the step
        the stamps' way (the pages only ever raise a numbering: ``holepages``)."""
        tracker = self._tracker
        if hold.stamps_kept is None:  # asked once, when its frames are in (no arrays per frame)
            numbered = window_step(tracker.window, tracker.placer.halves, hold.seq)
            hold.stamps_kept = (numbered is None or numbered >= hold.periods
                                or not _read_at_once(tracker.window, hold.seq))
        return (not hold.heard or hold.stamps_kept
                or tracker.placer.seen.told_after(hold.t_s))

    def holds(self, sample: Held) -> bool:
        """Whether the on-board sample (its pose, ODOM_POSE_Y half and whether it queued:
        ``tracking.PoseTracker.compare``'s arguments) waits: its pose names a held step's
        frame or later. It is compared when the hold ends, by the stall rules too, in order."""
        if not self.pending or sample[0].seq < self.pending[0].seq:
            return False
        self.held.append(sample)
        return True

    def decide(self, t_s: float = math.inf) -> None:
        """The holds whose time is up at bus time ``t_s`` end (default: all of them: the
        reference restarts, the watch ends)."""
        ready = 0
        while ready < len(self.pending) and self.pending[ready].until_s < t_s:
            ready += 1
        self._release(ready)

    def _release(self, count: int) -> None:
        """End the first ``count`` holds: compare the samples held that name frames before the
        next hold's (all when none waits), in order (``tracking.PoseTracker.compare``: the
        placement numbers the window as it now stands)."""
        if not count:
            return
        self.pending = self.pending[count:]
        self.until_s = self.pending[0].until_s if self.pending else math.inf
        below = self.pending[0].seq if self.pending else math.inf
        now = [sample for sample in self.held if sample[0].seq < below]
        self.held = [sample for sample in self.held if sample[0].seq >= below]
        for sample in now:
            self._tracker.compare(*sample)


def _read_at_once(window: Columns, seq: int) -> bool:
    """Whether encoder frame ``seq`` and the one after it (in the tracker's ``window`` of
    ``ENC_WINDOW`` frames) were stamped at once (``AT_ONCE_S``): a recorder's backlog, whose
    chunk the pages may number; a busy bus lets its burst out frame by frame, and its pages,
    held too, are not waited for (the window's numbering stands, as before). Asked over the
    window's columns: a hold behind another is asked only when that one ends, and the latest
    ``RECENT`` rows had lost its frames then (a kobuki chunk of 34 periods, asked 56 frames
    on: numbered 2 without its pages, 1.8 mm placed short, POSE WRONG on a correct firmware)."""
    seqs = window.col("seq")
    i = int(np.searchsorted(seqs, seq))
    if i + 1 >= len(seqs) or int(seqs[i]) != seq or int(seqs[i + 1]) != seq + 1:
        return False
    stamps = window.col("t_s")
    return bool(stamps[i + 1] - stamps[i] < AT_ONCE_S)
