"""A sample whose halves straddle a silence, its ODOM_POSE_Y read queued: the firmware's first
after a stall, or a burst's, told by the sample after it (issue #11: a FAIL must never blame a
correct firmware; the live half of ``stalls.after_stalls``' ``queued``).

``analyze`` tells a sample the bus let out in a burst from the firmware's first sample after a
silence by the samples' own times (``queued_frames`` over their ODOM_POSE_Y bus times: less than
``QUEUED_GAP_CYCLES`` cycles from the sample before or after it); the first after a silence not
so queued it leaves out, and the reference's position is placed again at the next
(``livestall`` is that rule live). The live judges took a sample's ``queued`` from its
ODOM_POSE_Y half's naming (``queued_frames`` over the Y halves): the same, except where a close
Y half makes no sample. A firmware halted (SIGSTOP 2 s) between a tick's ODOM_POSE_X and the
rest of it sends that tick's ODOM_POSE_Y on resuming, 1 ms before its next tick's, which then
names no frame (the queued naming chain, ``queuednames``: its X is lone). The halted tick's Y
read queued, its sample was judged as a burst's, and the silence before it told no stall: the
next sample was judged against the reference stepped across the stall, POSE WRONG 64.0 mm on
pmir, 226.2 mm on kobuki (its re-prime missed), on the correct firmware, which ``analyze``
PASSed (``tests/test_halted_send.py``).

So such a sample, its ODOM_POSE_X heard a silence before its ODOM_POSE_Y (the firmware fell
silent between its halves: a halt mid-tick, or its node bus-off), waits (``holds``) for the
next sample made (``paired``): sent less than ``QUEUED_GAP_S`` after it, a burst's (judged
queued, as before); later (or a reference restarted since), the firmware's first after the
stall: judged not queued, so the stall rule leaves it out and owes the placement, and a long
stall's re-prime hold starts there (``livereprime``), as ``analyze`` leaves it out. It is
judged before the lone halves heard before that next sample are (``livelone``: after the
latest sample compared only). A sample whose halves both came after the silence (the bus let
the poses out at once) is judged as before: queued, compared at once, the lone halves among
its burst judged after it (``analyze`` may read such a burst, its samples apart, as a stall:
the live judges judge its poses as sent, which a correct firmware meets).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livewindow import CYCLE_S, QUEUED_GAP_S, silent_since
from odocan.host.judge.samples import SILENCE_CYCLES

if TYPE_CHECKING:
    from odocan.host.judge.livepose import FramePose, Sample
    from odocan.host.judge.livewindow import Half
    from odocan.host.judge.tracking import PoseTracker

QUIET_S = (SILENCE_CYCLES - 0.5) * CYCLE_S  # halves this far apart straddle a silence


class QueuedFirst:
    """The tracker's hold of a queued sample straddling a silence (module docstring)."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        # the sample held (pose, its ODOM_POSE_Y half) and the stall rule's last sample time
        self._held: tuple[FramePose, Half, float | None] | None = None
        self._sample: Sample | None = None  # its settled sample, unjudged (``sampled``)
        self._x_s = 0.0  # the ODOM_POSE_X bus time of the latest sample made (``paired``)
        self._judging = False  # (its judgement: not held again)

    def paired(self, seq: int, x_s: float, y_s: float) -> None:
        """The sample of encoder frame ``seq`` is made (its ODOM_POSE_X and ODOM_POSE_Y at bus
        times ``x_s``, ``y_s``; ``livehalves``): a sample held before it is judged first."""
        self._x_s, held = x_s, self._held
        if held is not None and seq > held[0].seq:
            self._held = None
            self._judge(held, y_s - held[1].t_s < QUEUED_GAP_S)

    def holds(self, pose: FramePose, y: Half, queued: bool) -> bool:
        """Whether the sample ``pose`` (its ODOM_POSE_Y ``y``, ``queued`` by its naming) waits
        for the next sample made (module docstring)."""
        tracker, stall = self._tracker, self._tracker.stall
        if (self._judging or self._held is not None or not queued or pose is not tracker.pose
                or y.t_s - self._x_s < QUIET_S or tracker.raw.odometry is None
                or not silent_since(stall.last_t_s, y.t_s, tracker.pairs.halves["y"],
                                    tracker.window)):
            return False  # (``pose is not tracker.pose``: another hold's, released: as it comes)
        self._held, self._sample = (pose, y, stall.last_t_s), None
        return True

    def sampled(self, sample: Sample) -> None:
        """A sample settled unjudged: kept when held, settled again once judged."""
        held = self._held
        if held is not None and sample.reference is None and held[0].seq == sample.pose.seq:
            self._sample = sample

    def _judge(self, held: tuple[FramePose, Half, float | None], burst: bool) -> None:
        """Judge the sample held: a ``burst``'s as queued, else as not queued (the stall
        rule's first after its silence); a reference restarted since: left out."""
        tracker = self._tracker
        pose, y, last_s = held
        sample, self._sample = self._sample, None
        if tracker.raw.odometry is None or tracker.stall.last_t_s != last_s:
            return  # the reference started again since: not its sample
        self._judging = True
        try:
            ref = tracker.compare(pose, y, burst)
        finally:
            self._judging = False
        if sample is not None and ref is not None:
            tracker.settled.append(sample._replace(reference=ref))
