"""The live half of ``host.judge.stallreprime`` (issue #11, rule 5: a FAIL must never blame a
correct firmware): a stall the firmware re-primed after, by its own word.

After a stall long enough for the firmware's step bound to reach the ambiguous step
(``stallreprime.possible``: the silence since its last ODOM_STATUS), the correct firmware may
have re-primed on the frame it took on resuming (COUNTER_RESET): the stall's motion is not in
its pose, and its heading leaves the reference's. Its word comes in its next summary
(``nearthreshold``'s rule: COUNTER_RESET set there, clear on the last summary before the stall),
after its first poses. So the samples after such a stall are held, unjudged
(``ReprimeHold.holds``), until a summary made ``AFTER_PERIODS`` after the stall's first sample
is heard, or ``WAIT_S`` passed. Declared: the reference restarts from the next on-board pose
(``livedark.DarkRestarts.owe``, as at a step near the threshold: ``livenewstart`` fits its start
over a second of samples), told by an event with ``stallreprime.detail``; the firmware's own
DEGRADED state shows. Not declared (or no word in time): the samples held are judged as they
would have been, by the stall's position placement, the heading exact.

A declared re-prime whose first pose lies farther from the firmware's position before the
stall (its last sample compared, or the power-up pose) than it can have moved over the frames
its FIFO kept (at the speed bound) and from the frame it re-primed on (the window's counts) is
no re-prime's (``_plausible``): judged as before, POSE WRONG (a firmware X +1 m off after a 6 s
stall was adopted, DEGRADED only). Known limit (``analyze`` bounds it tighter): within that
bound (pmir at 4 m/s: about 0.2 m plus the few frames' travel) the new start adopts the
firmware's pose, so one pose jump there is not judged live; every step after it is.
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING, Any

from odocan.host.judge.livewindow import CYCLE_S
from odocan.host.judge.nearthreshold import AFTER_PERIODS, COUNTER_RESET_BIT, SUMMARY_PAGE
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.host.judge.stallreprime import FIFO_SPAN, R_SPAN, detail, possible

if TYPE_CHECKING:
    from odocan.host.judge.livepose import FramePose, Sample
    from odocan.host.judge.livewindow import Half
    from odocan.host.judge.tracking import PoseTracker

WAIT_S = 1.0  # bus time the samples after a long stall wait for the firmware's word (s)


class ReprimeHold:
    """The tracker's hold of the samples after a long stall (module docstring)."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        self._mask = -1  # ERROR_MASK of the latest summary heard (-1: none)
        self._before = -1  # ... of the latest before the stall held for
        self._stall_s = 0.0  # the stall's silence (s)
        self._from_s = math.inf  # bus time of the stall's first sample (s; inf: no hold)
        self._first = -1  # its encoder frame (seq)
        self._anchor: tuple[float, float] | None = None  # the firmware's position before (m)
        self._held: list[tuple[FramePose, Half, bool]] = []
        self._samples: dict[int, Sample] = {}
        self.declared = 0  # re-primes declared after a stall (the reference restarted)

    def on_status(self, signals: dict[str, Any], t_s: float) -> None:
        """An accepted ODOM_STATUS (raw signals) at bus time ``t_s``: a summary decides the
        hold when made after it."""
        if int(signals.get("PAGE", -1)) != SUMMARY_PAGE or "ERROR_MASK" not in signals:
            return
        self._mask = int(signals["ERROR_MASK"])
        if t_s >= self._from_s + AFTER_PERIODS * CYCLE_S:
            said = self._before >= 0 and not self._before & COUNTER_RESET_BIT
            self.release(said and bool(self._mask & COUNTER_RESET_BIT))

    def stalled(self, seq: int, t_s: float, talked: tuple[float, int] | None,
                least: int | None) -> None:
        """The sample of encoder frame ``seq`` (its ODOM_POSE_Y at ``t_s``) was left out after
        a stall (``livestall``, ``livefirst``), the firmware's last ODOM_STATUS ``talked``
        (bus time, ``livefirst.FirstStall.talked_before``): the samples after it are held when
        the stall was long enough."""
        if talked is None or self._from_s != math.inf:
            return
        if possible(t_s - talked[0], CYCLE_S, least) and self._mask >= 0:
            self._from_s, self._before, self._stall_s = t_s, self._mask, t_s - talked[0]
            self._first, self._anchor = seq, self._anchored()

    def _anchored(self) -> tuple[float, float] | None:
        """Where the firmware was before the stall: its last sample compared, or the power-up
        pose the reference runs from (``livefirst``: a stall before the life's first sample);
        None when unknown (no bound then)."""
        tracker = self._tracker
        last = tracker.stall.last_compared
        if tracker.last_pair is not None and tracker.last_pair[0].seq == last:
            return tracker.last_pair[0].x_m, tracker.last_pair[0].y_m
        return (0.0, 0.0) if tracker.first.stalled_from == last else None

    def _plausible(self, pose: FramePose) -> bool:
        """Whether the firmware's first pose after the re-prime lies within what it can have
        moved from ``_anchor``: over the frames its FIFO kept (``FIFO_SPAN`` and one more
        periods at the speed bound) and from the frame it re-primed on (the first left out,
        ``R_SPAN`` before at most) to this one (the window's counts), each within its travel,
        plus a position LSB each."""
        if self._anchor is None:
            return True
        tracker = self._tracker
        gate, geometry = tracker.raw.gate, tracker.geometry
        per_period_m = max(gate.bound[0] * geometry.m_per_count_left,
                           gate.bound[1] * geometry.m_per_count_right)
        since = min(self._first, pose.seq - R_SPAN) - 1
        rows = [r for r in tracker.window.rows if since <= r[0] <= pose.seq]
        travel_m = (FIFO_SPAN + 1) * per_period_m
        if len(rows) < 2 or int(rows[0][0]) != since:  # its frames not all in the window
            travel_m += (pose.seq - since) * per_period_m
        else:
            for a, b in itertools.pairwise(rows):
                travel_m += max(
                    abs(_wrapped(int(b[4]) - int(a[4]), gate.bits)) * geometry.m_per_count_left,
                    abs(_wrapped(int(b[5]) - int(a[5]), gate.bits)) * geometry.m_per_count_right)
        return math.hypot(pose.x_m - self._anchor[0], pose.y_m - self._anchor[1]) <= (
            travel_m + 2 * POSITION_LSB_M)

    def holds(self, pose: FramePose, y: Half, queued: bool) -> bool:
        """Whether the sample ``pose`` waits for the firmware's word (judged at ``release``)."""
        if self._from_s == math.inf:
            return False
        if y.t_s > self._from_s + WAIT_S:  # no word in time: not declared
            self.release(False)
            return False
        self._held.append((pose, y, queued))
        return True

    def sampled(self, sample: Sample) -> None:
        """A sample settled unjudged: kept when held, settled again once judged."""
        if self._held and sample.reference is None and self._held[-1][0].seq == sample.pose.seq:
            self._samples[sample.pose.seq] = sample

    def release(self, declared: bool) -> None:
        """End the hold: ``declared``, the reference restarts from the first sample held (the
        event told); else the samples held are judged as they came."""
        if self._from_s == math.inf:
            return
        held, self._held, self._from_s = self._held, [], math.inf
        samples, self._samples = self._samples, {}
        tracker = self._tracker
        if declared and held and not self._plausible(held[0][0]):
            declared = False  # a jump no re-prime explains: judged as before (POSE WRONG)
        if declared:
            self.declared += 1
            first = held[0][0].seq if held else self._first + 1
            tracker.placer.dark.owe(first)
            tracker.restarts.events.append({"t_s": self._from_s_told(held), "kind":
                                            "stall_reprime", "encoder_frame": first,
                                            "detail": detail(self._stall_s)})
        for pose, y, queued in held:
            tracker.placer.dark.due(pose.seq, tracker.newstart.restart)
            ref = tracker.compare(pose, y, queued)
            sample = samples.get(pose.seq)
            if sample is not None and ref is not None:
                tracker.settled.append(sample._replace(reference=ref))

    def _from_s_told(self, held: list[tuple[FramePose, Half, bool]]) -> float:
        """The event's bus time: the first sample held's (the tracker's latest without one)."""
        return held[0][1].t_s if held else self._tracker.now_s


def _wrapped(delta: int, bits: int) -> int:
    """A count step read in ``bits``-bit counters (signed)."""
    half = 1 << (bits - 1)
    return (delta + half) % (2 * half) - half
