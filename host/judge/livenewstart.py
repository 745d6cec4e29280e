"""The live judge's samples after an unseen restart, held until its new start is fitted (issue
#11, rule 5: a FAIL must never blame a correct firmware; ``host.judge.livedark``,
``host.judge.newstartfit``).

After an unseen controller restart the live reference starts again from the next on-board pose
(``livedark.DarkRestarts``): its position and heading are that pose's, within their rounding,
and the start fit (``livefit.LiveFit``) narrows them as the life's samples come. Judged as they
came, its first samples were judged by a fit of one sample, two, three: the live reference's
own error there was that pose's rounding, up to 0.6 position LSB (against float64 odometry),
where ``analyze`` fits the new start over the whole life (``newstartfit``) and judges every
sample by it. Now the new life's samples are held, unjudged, for ``HOLD_S`` of bus time from
its first (each fed to the fit as it comes), then judged by the fit made of all of them, and
the samples after by the fit as it goes on (causal: each fed before it is judged). The live
verdict there lags by at most ``HOLD_S``; a pose wrong beyond what the start's rounding
explains is still POSE WRONG (the fit never leaves the intervals the samples prove, and does
not take a sample outside them: ``livefit.LiveFit.refused``). The samples held are judged
early, by the fit so far, when the reference is placed again (a stall, a gap:
``liveplacing``) or restarts.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from odocan.host.judge.livepose import FramePose, Sample

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

HOLD_S = 1.0  # bus time the new life's samples wait from its first (s): the verdict's lag


class NewStartHold:
    """The tracker's hold of a new life's samples after an unseen restart (module docstring)."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        self._armed = False  # the next reference start is an unseen restart's new start
        self.until_s = math.inf  # bus time the samples held are judged at (s)
        self._held: list[tuple[FramePose, FramePose, float]] = []  # pose, raw ref, t (s)
        self._samples: dict[int, Sample] = {}  # the samples held by encoder frame
        self.holds_made = 0  # new starts whose samples were held

    def restart(self) -> None:
        """An unseen restart (``livedark.DarkRestarts.due``): the reference starts again at the
        next pose, whose life's samples are held."""
        self._tracker.restart_reference()
        self._armed = True

    def started(self, exact: bool) -> None:
        """The reference started (``livestart``): an armed hold opens at a fitted start (an
        ``exact`` one, a power-up's, has nothing to wait for)."""
        armed, self._armed = self._armed, False
        if armed and not exact:
            self.until_s = self._tracker.pose_t_s + HOLD_S
            self.holds_made += 1

    def holds(self, pose: FramePose, raw: FramePose) -> bool:
        """Whether ``pose`` (the raw reference ``raw`` at its frame) waits: fed to the fit
        now, judged at ``release``; it counts as compared for the stall rules."""
        if self.until_s == math.inf:
            return False
        tracker = self._tracker
        tracker.fit.feed(pose, raw)
        tracker.placer.compared(pose)
        tracker.stall.last_compared, tracker.stall.compared_t_s = pose.seq, tracker.pose_t_s
        self._held.append((pose, raw, tracker.pose_t_s))
        return True

    def sampled(self, sample: Sample) -> None:
        """A sample settled unjudged: kept when held, settled again once judged."""
        if sample.reference is None and self._held and self._held[-1][0].seq == sample.pose.seq:
            self._samples[sample.pose.seq] = sample

    def release(self) -> None:
        """Judge the samples held by the fit made of them (the hold ends)."""
        held, self._held, self.until_s = self._held, [], math.inf
        samples, self._samples = self._samples, {}
        tracker = self._tracker
        for pose, raw, t_s in held:
            ref = tracker.record(pose, raw, fed=True, t_s=t_s)
            sample = samples.get(pose.seq)
            if sample is not None:
                tracker.settled.append(sample._replace(reference=ref))
