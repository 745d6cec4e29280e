"""The live half of ``host.judge.cutreprime`` (issue #11, both ways: a correct firmware said
POSE WRONG, a firmware 1 m off the staged pose said OK): an APPLY with X, Y and HEADING staged
a few ticks after a stall the firmware may re-prime after.

The firmware drains its FIFO's backlog after the stall, takes the APPLY, then re-primes on the
first fresh encoder frame after it (COUNTER_RESET): it holds the staged pose to that frame and
steps plainly from it. Before, ``apply_set_pose`` started the reference exactly at the staged
pose, but the stall's owed placement (``livefirst``: the first sample after the restart left out
as a stall's, the next placed within the stall's allowance) absorbed any offset, 1 m too; and the
stall's re-prime hold (``livereprime``), released after the APPLY, replayed from the pose before
the stall or adopted the next pose. Where neither did, the reference stepped into the re-prime
frame, one frame's turn off the correct firmware (POSE WRONG).

So at such an APPLY (the stall's re-prime hold pending: a stall long enough, its first sample
left out just before) ``CutHold.arm`` ends that hold (the samples it held are the old life's),
owes no placement (the pose is exact), and holds the next ``COMPARED`` samples; then the
reference holds the staged pose to frame ``r``, ``r`` the APPLY's frame (nothing held) or one
from ``R_SPAN`` frames before the first sample that moved up to it, whichever path best meets
the samples held (``cutreprime._chosen``'s score), and they are judged. What a wrong firmware
can hide there: a heading off by the turn of those few frames; its position is held to the exact
staged pose (1 m, 10 mm off: POSE WRONG). The frames not in the window: the choice is not made
(the start stays at the APPLY's frame) and the end verdicts say UNJUDGED
(``livereprime.unbounded_why``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from odocan.host.judge.livefit import LiveFit
from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livereprime import WAIT_S
from odocan.host.judge.livestart import start_reference
from odocan.host.judge.livewindow import CYCLE_S, window_counts
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.stallreprime import COMPARED, R_SPAN, possible

if TYPE_CHECKING:
    from odocan.host.judge.livepose import Sample
    from odocan.host.judge.livewindow import Half
    from odocan.host.judge.tracking import PoseTracker

_TURN = 2.0 * math.pi


class CutHold:
    """The samples after a staged APPLY just after a long stall, held for the choice of the
    frame the firmware re-primed on (module docstring)."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        self.pending: FramePose | None = None  # the staged pose on the APPLY's frame
        self._from_s = math.inf  # bus time of the APPLY's ACK (s)
        self._held: list[tuple[FramePose, Half, bool]] = []
        self._samples: dict[int, Sample] = {}
        self.unchosen = 0  # choices not made: the frames not in the window

    def arm(self, pose: FramePose) -> None:
        """An APPLY with all fields staged restarted the reference exactly at ``pose``. Held
        only while a long stall's re-prime hold would be (module docstring). The stall's
        silence ends here, at the APPLY: measured from the last sample before the stall (issue
        #11, a stall 10 s after a reset), the first sample held was left out again as the
        stall's when judged at ``release``, and the stall's re-prime hold, declared by
        COUNTER_RESET, restarted the reference at the firmware's own pose (10 mm off: OK)."""
        tracker = self._tracker
        talked = tracker.first.made_before(tracker.now_s)
        if talked is None or not possible(tracker.now_s - talked[0], CYCLE_S,
                                          tracker.raw.gate.least):
            return
        tracker.reprime.release(False)  # a hold pending: its samples held are the old life's
        # no placement owed (``livefirst``): the pose is exact, the silence ends at the APPLY
        tracker.stall.heard_first(tracker.now_s)
        self.pending, self._from_s, self._held = pose, tracker.now_s, []

    def holds(self, pose: FramePose, y: Half, queued: bool) -> bool:
        """Whether the sample ``pose`` waits for the choice (made once ``COMPARED`` are held,
        or ``WAIT_S`` passed)."""
        if self.pending is None:
            return False
        if y.t_s > self._from_s + WAIT_S:
            self.release()
            return False
        self._held.append((pose, y, queued))
        if len(self._held) >= COMPARED:
            self.release()
        return True

    def sampled(self, sample: Sample) -> None:
        """A sample settled unjudged: kept when held, settled again once judged."""
        if self._held and sample.reference is None and self._held[-1][0].seq == sample.pose.seq:
            self._samples[sample.pose.seq] = sample

    def release(self) -> None:
        """Choose the frame, restart the reference there, judge the samples held."""
        start, self.pending = self.pending, None
        held, self._held = self._held, []
        samples, self._samples = self._samples, {}
        if start is None:
            return
        tracker = self._tracker
        r = self._chosen(start, [pose for pose, _, _ in held])
        if r is None:
            self.unchosen += 1
        elif r != start.seq:
            self._restart(start._replace(seq=r))
        for pose, y, queued in held:
            ref = tracker.compare(pose, y, queued)
            sample = samples.get(pose.seq)
            if sample is not None and ref is not None:
                tracker.settled.append(sample._replace(reference=ref))

    def _restart(self, start: FramePose) -> None:
        """The reference held at the staged pose to frame ``start.seq``, stepped from there."""
        tracker = self._tracker
        counts = window_counts(tracker.window, start.seq)
        start_reference(tracker, start, counts, [])
        tracker.fit = LiveFit(start.x_m, start.y_m, exact=True)
        tracker.restarts.events.append({
            "t_s": self._from_s, "kind": "stall_reprime", "encoder_frame": start.seq,
            "detail": "the staged APPLY taken just after a long stall, the firmware re-primed "
                      f"after it: its staged pose held to encoder frame {start.seq}"})

    def _chosen(self, start: FramePose, poses: list[FramePose]) -> int | None:
        """The frame ``r`` whose held path best meets ``poses`` (module docstring); None when
        the reference's frames are not all known."""
        at = self._tracker.raw.at
        moved = [p.seq for p in poses if p.seq > start.seq]
        if not moved:
            return start.seq
        first = moved[0]
        candidates = [start.seq, *range(max(start.seq + 1, first - R_SPAN), first + 1)]
        path = {s: at.get(s) for s in {*candidates, *(p.seq for p in poses)}}
        if any(p is None for p in path.values()):
            return None
        best: tuple[float, int] | None = None
        for r in candidates:
            score = max(_off(start, path[r], path[max(p.seq, r)], p) for p in poses)  # type: ignore[arg-type]
            if best is None or score < best[0]:
                best = (score, r)
        assert best is not None
        return best[1]


def _off(start: FramePose, held: FramePose, ref: FramePose, pose: FramePose) -> float:
    """How far ``pose`` lies from the staged ``start`` moved by the reference's motion from
    ``held`` to ``ref``, in LSBs (position plus heading)."""
    turn = start.heading_rad - held.heading_rad
    c, s = math.cos(turn), math.sin(turn)
    dx, dy = ref.x_m - held.x_m, ref.y_m - held.y_m
    ex = start.x_m + c * dx - s * dy - pose.x_m
    ey = start.y_m + s * dx + c * dy - pose.y_m
    eh = (turn + ref.heading_rad - pose.heading_rad + math.pi) % _TURN - math.pi
    return math.hypot(ex, ey) / POSITION_LSB_M + abs(eh) / HEADING_LSB_RAD

