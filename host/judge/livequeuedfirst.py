"""A sample whose ODOM_POSE_Y read queued right after a silence: a burst's, or the firmware's
first after a stall, told by the sample after it (issue #11: a FAIL must never blame a correct
firmware; the live half of ``stalls.after_stalls``' ``queued``).

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

So such a sample waits (``holds``) for the next one compared: sent less than
``QUEUED_GAP_S`` after it, a burst's (judged queued, as before); later (or a reference
restarted since), the firmware's first after the stall: judged not queued, so the stall rule
leaves it out and owes the placement, and a long stall's re-prime hold starts there
(``livereprime``), as ``analyze`` leaves it out. No next sample: left out, as ``analyze``
leaves a sample after a silence with none close after it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livewindow import QUEUED_GAP_S, silent_since

if TYPE_CHECKING:
    from odocan.host.judge.livepose import FramePose, Sample
    from odocan.host.judge.livewindow import Half
    from odocan.host.judge.tracking import PoseTracker


class QueuedFirst:
    """The tracker's hold of a queued sample after a silence (module docstring)."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        # the sample held (pose, its ODOM_POSE_Y half) and the stall rule's last sample time
        self._held: tuple[FramePose, Half, float | None] | None = None
        self._sample: Sample | None = None  # its settled sample, unjudged (``sampled``)
        self._judging = False  # (its judgement: not held again)

    def holds(self, pose: FramePose, y: Half, queued: bool) -> bool:
        """Whether the sample ``pose`` (its ODOM_POSE_Y ``y``, ``queued`` by its naming) waits
        for the next; a sample held before it judged first (module docstring)."""
        tracker, held = self._tracker, self._held
        if self._judging:
            return False
        if held is not None and pose.seq > held[0].seq:
            self._held = None
            self._judge(held, y.t_s - held[1].t_s < QUEUED_GAP_S)
        elif held is not None:  # (one held back longer, judged at its release: not the next)
            return False
        stall = tracker.stall  # (a sample another hold releases is judged as it comes)
        if (not queued or pose is not tracker.pose or tracker.raw.odometry is None
                or stall.last_t_s is None
                or not silent_since(stall.last_t_s, y.t_s, tracker.pairs.halves["y"],
                                    tracker.window)):
            return False
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
