"""The live judge's choice at an ambiguous hole no page has told of yet (issue #11, one judge;
rule 3: a FAIL must never blame a correct firmware, rule 5: a PASS must never hide a wrong
pose; ``host.judge.evidenceless``).

A step of the encoder frames heard that reaches the ambiguous step (``host.judge.ambiguity``)
behind a hole of the frames heard re-primes the reference (``livepose.StepGate``), as the
firmware does when it missed the frames; a recorder (or a link) that lost the frames alone holds
a firmware that took them one by one. Where the pages heard when it steps do not prove frames
taken in the hole (``livepose.StepGate._taken``), the whole log's judge chooses by the
firmware's next pose (``host.judge.evidencechoice``: the candidate nearer to it, in LSBs of
position and heading) unless its pages prove the gap missed. The live judge did not choose:
with no page of the life to tell (no FRAME_TOTALS page, no ENC_E2E page inside the hole:
``LiveSeen.heard_in``) it started again from the next pose, so a firmware whose HEADING was
2 LSB off after such a hole FAILed ``analyze`` and PASSed the monitor and the bridge; with
one, it stayed re-primed, so a firmware that took a short recorder hole, which no page
decides, FAILed the monitor and the bridge (22.5 mm on a fast robot) and PASSed ``analyze``.

Now both candidates are kept: the reference re-primed (the gate's) and its twin that took the
hole's step (the frames' counts across it, ``wrap_delta``), stepped along with it frame by
frame. The on-board samples naming the hole's frame or later are held, unjudged, until the pages
had their time: ``WAIT_S`` of bus time after the hole when no page of the life was heard before
it; when one was, until an ENC_E2E page sent after the hole and a FRAME_TOTALS page after that
one are kept (``LiveSeen.told_after``: the first window over the hole a proof can close; about
1.2 s at the firmware's page rotation), at most ``PAGES_WAIT_S`` (the pages that prove a silence
missed must not come after the choice: 932077b kept the re-prime there for that), or the end
of the watch or the reference's restart. Then the pages heard decide as they decide for the
whole log (the gap proven missed: ``Seen.gap_missed``, the re-prime), else the first held
sample chooses as ``evidencechoice`` does, and every held sample is judged against the chosen
candidate (the gap taken keeps its placement, ``gapbound``'s allowance; the re-prime none). A
live verdict so lags the hole by at most ``PAGES_WAIT_S``; a pose that fits neither FAILs.
Bounded: one choice at a time, its twin's poses over ``PAGES_WAIT_S`` of frames. A hole of the
frames heard while one waits makes it first (``ahead``), before the new gap is placed or the
reference steps into it: from its first held sample, as it would be later (so a second such hole
holds its own choice), unless it waits for pages (then a second such hole holds a choice of
its own, made by its first sample as ``analyze`` makes it: ``livesecond``; a third falls back:
the re-prime) or holds no sample yet (then a second such hole falls back to the new start from
the next pose, ``livedark.DarkRestarts.owe``).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from odocan.host.judge import livesecond
from odocan.host.judge.liveplace import Gap
from odocan.host.judge.livepose import FramePose, difference
from odocan.host.judge.livewindow import CYCLE_S
from odocan.host.judge.reference import ReferenceOdometry
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK as MASK

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

WAIT_S = 1.0  # bus time after the hole's frame the pages may take to tell (s)
ROW_COUNTER, ROW_T_S = 2, 3  # the tracker's window rows (``tracking.PoseTracker.on_encoders``)
PAGES_WAIT_S = 3.0  # ... at most, pages of the life heard before it (five page rotations, s)


@dataclass
class Pending:
    """A choice waiting: the frame after the hole, the bus times of the frames around it, the
    twin that took its step and its poses by frame, the hole's gap (a placement part when
    taken), the last sample compared before it, the samples held since; whether pages of the
    life were heard before it (``LiveSeen.heard_in``: the pages after it are waited for)."""

    seq: int
    span_s: tuple[float, float]
    heard: bool
    twin: ReferenceOdometry
    gap: Gap | None
    last_compared: int
    twin_at: dict[int, FramePose] = field(default_factory=dict)
    held: list[FramePose] = field(default_factory=list)


class LiveChoice:
    """The tracker's choice at an ambiguous hole no page told of (module docstring)."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        self.pending: Pending | None = None
        self.second: livesecond.Second | None = None  # a hole's while one waits (livesecond)
        self.until_s = math.inf  # bus time the pending choice is decided at (s)
        self.taken = self.reprimed = 0  # choices made each way

    def open(self, seq: int, span_s: tuple[float, float], taken: tuple[int, int]) -> bool:
        """The reference re-primes on encoder frame ``seq`` after a hole from bus time
        ``span_s[0]`` to ``span_s[1]`` whose frames' step was ``taken`` (counts): hold the
        choice (True), or False (a choice waits already, or no reference: a new start owed)."""
        ref = self._tracker.raw.odometry
        if self.pending is not None and ref is not None:
            return self._second(seq, span_s, taken, ref)
        if ref is None:
            return False
        twin = copy.copy(ref)
        twin.step_deltas(*taken)
        heard = self._tracker.placer.seen.heard_in(*span_s)
        self.pending = Pending(seq, span_s, heard, twin, self._tracker.placer.gap_at(seq),
                               self._tracker.stall.last_compared)
        self.until_s = span_s[1] + (PAGES_WAIT_S if heard else WAIT_S)
        return True

    def _second(self, seq: int, span_s: tuple[float, float], taken: tuple[int, int],
                ref: ReferenceOdometry) -> bool:
        """A hole while a choice waits for its pages: a second choice held
        (``livesecond``; True), or False (one held already, no sample held before it to
        move from, or the waiting choice waits for no page: it is made at the hole)."""
        p = self.pending
        assert p is not None
        if self.second is not None or not p.heard or not p.held:
            return False
        self.second = livesecond.opened(seq, span_s, p.held[-1], (ref, p.twin), taken,
                                        self._tracker.placer.gap_at(seq))
        return True

    def _second_made(self, pose: FramePose) -> None:
        """The second choice made at ``pose``, the first sample naming its frame or later
        (``livesecond.take``): taken, the reference and the first choice's twin become the
        twins that took its step."""
        second, self.second = self.second, None
        assert second is not None and self.pending is not None
        tracker = self._tracker
        seen = tracker.placer.seen
        if (seen.heard_in(*second.span_s) and seen.proven().gap_missed(second.seq)) or (
                not livesecond.take(second, tracker.raw.at, pose)):
            self.reprimed += 1
            return
        self.taken += 1
        tracker.raw.odometry = second.twin
        if not tracker.raw.blind:
            tracker.raw.at.update(second.twin_at)
        self.pending.twin = second.first_twin
        self.pending.twin_at.update(second.first_twin_at)
        if second.gap is not None:
            tracker.placer.took_gap(second.gap)

    def paged(self, t_s: float) -> None:
        """A FRAME_TOTALS page kept at bus time ``t_s``: when pages were heard before the hole
        and those a proof over it needs are in, the choice is made at the next frame."""
        p = self.pending
        if p is not None and p.heard and self._tracker.placer.seen.told_after(p.span_s[1]):
            self.until_s = min(self.until_s, t_s)

    def stepped(self, seq: int, step: tuple[int, int] | None) -> None:
        """Encoder frame ``seq`` stepped the reference by ``step``: the twin steps too (the hole's
        frame it stepped at ``open``)."""
        p = self.pending
        assert p is not None
        if step is not None and seq != p.seq:
            p.twin.step_deltas(*step)
        p.twin_at[seq] = FramePose(seq, p.twin.x_m, p.twin.y_m, p.twin.heading_rad)
        if self.second is not None:
            livesecond.stepped(self.second, seq, step)

    def holds(self, pose: FramePose) -> bool:
        """Whether the on-board ``pose`` waits for the choice (it names the hole's frame or
        later); then it counts as compared for the stall rule (``livestall``)."""
        p = self.pending
        if p is None or pose.seq < p.seq:
            return False
        p.held.append(pose)
        stall = self._tracker.stall
        stall.last_compared, stall.compared_t_s = pose.seq, self._tracker.pose_t_s
        if self.second is not None and pose.seq >= self.second.seq:
            self._second_made(pose)
        return True

    def ahead(self, counter: int, t_s: float, prev: tuple[float, ...]) -> None:
        """An encoder frame (COUNTER, bus time ``t_s``) heard after the window's row ``prev``
        while a choice waits: when the frames heard have a hole before it (COUNTER not the
        next, or late by half a period), the choice is made now if a sample is held and no
        page is waited for (module docstring)."""
        p = self.pending
        assert p is not None
        if p.heard or not p.held:
            return
        if (counter - int(prev[ROW_COUNTER])) & MASK != 1 or t_s - prev[ROW_T_S] > 1.5 * CYCLE_S:
            self.decide()

    def decide(self) -> None:
        """Choose (module docstring) and judge the samples held against the chosen reference,
        placed after the hole as any gap's (``tracking.PoseTracker.judge``)."""
        p, self.pending, self.until_s = self.pending, None, math.inf
        if p is None:
            return
        if self.second is not None:  # its sample not come: the re-prime (livesecond)
            self.second = None
            self.reprimed += 1
        tracker = self._tracker
        if self._take(p):
            self.taken += 1
            tracker.raw.odometry = p.twin
            if not tracker.raw.blind:  # a blind reference keeps none (livereference)
                tracker.raw.at.update(p.twin_at)
            if p.gap is not None:
                tracker.placer.took_gap(p.gap)
        else:
            self.reprimed += 1
        tracker.stall.last_compared, tracker.stall.compared_t_s = p.last_compared, None
        for pose in p.held:
            tracker.judge(pose)

    def _take(self, p: Pending) -> bool:
        """Whether the twin (the hole taken) is chosen: not where the pages heard prove the
        firmware missed the hole's frames; else by the first sample held (``evidencechoice``:
        strictly nearer, position and heading in LSBs)."""
        seen = self._tracker.placer.seen
        if seen.heard_in(*p.span_s) and seen.proven().gap_missed(p.seq):
            return False
        if not p.held:
            return False
        pose = p.held[0]
        reprimed, took = self._tracker.raw.at.get(pose.seq), p.twin_at.get(pose.seq)
        if reprimed is None or took is None:
            return False
        correct = self._tracker.fit.correct
        return _lsbs(pose, correct(took)) < _lsbs(pose, correct(reprimed))


def _lsbs(pose: FramePose, ref: FramePose) -> float:
    """How far ``pose`` lies from ``ref``: position and heading in LSBs, summed."""
    off = difference(pose, ref)
    return off["dpos_m"] / POSITION_LSB_M + abs(off["dheading_rad"]) / HEADING_LSB_RAD
