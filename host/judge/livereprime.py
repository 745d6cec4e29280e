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

Known limit (``analyze`` bounds it): the live new start adopts the firmware's pose after a
declared re-prime, so one pose jump there is not judged live (``analyze`` keeps the position
within the merge allowance of the frames its FIFO kept); every step after it is.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from odocan.host.judge.livewindow import CYCLE_S
from odocan.host.judge.nearthreshold import AFTER_PERIODS, COUNTER_RESET_BIT, SUMMARY_PAGE
from odocan.host.judge.stallreprime import detail, possible

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
            self._first = seq

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
