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
no re-prime's (``_reach_m``): judged as before, POSE WRONG (a firmware X +1 m off after a 6 s
stall was adopted, DEGRADED only). Known limit (``analyze`` bounds it tighter): within that
bound (pmir at 4 m/s: about 0.2 m plus the few frames' travel) the new start adopts the
firmware's pose, so one pose jump there is not judged live; every step after it is.

A stall before a life's first pose, the reference not started (a power-up's: its first summary
is the last before the stall), takes the same hold and the same bound from the power-up pose
(0, 0) once the power-up is proven (its first count page, made after the stall:
``sources.heard_before_live``; the word waits for it, ``counted``); a jump beyond it starts the
reference at the nearest point the bound reaches (``_start_within``: X +1 m after a 6 s or
10 s halt at power-up PASSed the bridge, DEGRADED only). Not proven, the first pose is adopted
unbounded: the end verdicts say UNJUDGED rather than PASS (``unbounded_why``).
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING, Any

from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livestart import start_reference
from odocan.host.judge.livewindow import CYCLE_S, window_counts
from odocan.host.judge.nearthreshold import AFTER_PERIODS, COUNTER_RESET_BIT, SUMMARY_PAGE
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.host.judge.stallreprime import FIFO_SPAN, R_SPAN, detail, possible

if TYPE_CHECKING:
    from odocan.host.judge.livepose import Sample
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
        self._power_up = False  # the stall came before the life's first pose, its start unknown
        self._word = False  # ... its re-prime declared, waiting for the count page's proof
        self._held: list[tuple[FramePose, Half, bool]] = []
        self._samples: dict[int, Sample] = {}
        self.declared = 0  # re-primes declared after a stall (the reference restarted)
        self.unbounded = 0  # ... at a power-up not proven: the first pose adopted unbounded

    def on_status(self, signals: dict[str, Any], t_s: float) -> None:
        """An accepted ODOM_STATUS (raw signals) at bus time ``t_s``: a summary decides the
        hold when made after it."""
        if int(signals.get("PAGE", -1)) != SUMMARY_PAGE or "ERROR_MASK" not in signals:
            return
        self._mask = int(signals["ERROR_MASK"])
        if t_s >= self._from_s + AFTER_PERIODS * CYCLE_S:
            said = self._before >= 0 and not self._before & COUNTER_RESET_BIT
            word = said and bool(self._mask & COUNTER_RESET_BIT)
            if word and self._power_up and not self._tracker.lives.power_up_proven:
                self._word = True  # its power-up's proof, the page after: ``counted``
                return
            self.release(word)

    def counted(self) -> None:
        """A count page was heard (after ``livestart.Lives.on_counts`` took its proof, and its
        start from frame 0 while the window holds it): a re-prime declared at a power-up is
        released."""
        if self._word:
            self.release(True)

    def word(self) -> tuple[int, bool]:
        """The frame of the first sample after the latest stall held for, and whether the
        firmware said it re-primed there (COUNTER_RESET clear before, set on the latest
        summary): ``livekept`` bounds a bare APPLY just after it (``reprimekept``)."""
        said = self._before >= 0 and not self._before & COUNTER_RESET_BIT
        return self._first, said and bool(self._mask & COUNTER_RESET_BIT)

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
            self._power_up = self._tracker.raw.odometry is None  # its origin told at release

    def _anchored(self) -> tuple[float, float] | None:
        """Where the firmware was before the stall: its last sample compared, or the power-up
        pose the reference runs from (``livefirst``: a stall before the life's first sample);
        None when unknown (no bound then)."""
        tracker = self._tracker
        last = tracker.stall.last_compared
        if tracker.last_pair is not None and tracker.last_pair[0].seq == last:
            return tracker.last_pair[0].x_m, tracker.last_pair[0].y_m
        return (0.0, 0.0) if tracker.first.stalled_from == last else None

    def _origin(self) -> tuple[float, float] | None:
        """Where the firmware was before the stall, at release: ``_anchor``; after a stall
        before the first pose of a life the reference had not started for, the power-up pose
        (0, 0) once the power-up is proven (its first count page: ``sources.heard_before_live``,
        made after the stall), None while it is not."""
        if not self._power_up:
            return self._anchor
        return (0.0, 0.0) if self._tracker.lives.power_up_proven else None

    def _reach_m(self, pose: FramePose) -> float:
        """How far the firmware's first pose after the re-prime can lie from where it was
        before the stall: over the frames its FIFO kept (``FIFO_SPAN`` and one more periods at
        the speed bound) and from the frame it re-primed on (the first left out, ``R_SPAN``
        before at most) to this one (the window's counts), each within its travel, plus a
        position LSB each."""
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
        return travel_m + 2 * POSITION_LSB_M

    def holds(self, pose: FramePose, y: Half, queued: bool) -> bool:
        """Whether the sample ``pose`` waits for the firmware's word (judged at ``release``)."""
        if self._from_s == math.inf:
            return False
        if y.t_s > self._from_s + WAIT_S:  # no word in time: not declared (no page: said)
            self.release(self._word)
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
        held, self._held, self._from_s, self._word = self._held, [], math.inf, False
        samples, self._samples = self._samples, {}
        tracker = self._tracker
        origin = self._origin()
        if declared and held and origin is not None:
            pose = held[0][0]
            reach_m = self._reach_m(pose)
            off_m = math.hypot(pose.x_m - origin[0], pose.y_m - origin[1])
            if off_m > reach_m:  # a jump no re-prime explains: judged as before (POSE WRONG)
                declared = False
                if self._power_up:  # no reference yet: from the nearest pose a re-prime reaches
                    self._start_within(pose, origin, reach_m / off_m)
        elif declared and self._power_up:  # its first pose adopted, no bound: never a PASS
            self.unbounded += 1
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

    def _start_within(self, pose: FramePose, origin: tuple[float, float], share: float) -> None:
        """Start the reference, at a power-up's first pose after a re-prime it cannot explain,
        at the point nearest ``pose`` that the re-prime reaches from ``origin`` (``share`` of
        the way), the firmware's heading taken (a re-prime re-places it): the samples are judged
        from there, at least as far off as the jump beyond the bound."""
        counts = window_counts(self._tracker.window, pose.seq)
        if not counts or counts[0][0] != pose.seq:  # its frame not heard: never a PASS
            self.unbounded += 1
            return
        start = FramePose(pose.seq, origin[0] + share * (pose.x_m - origin[0]),
                          origin[1] + share * (pose.y_m - origin[1]), pose.heading_rad)
        start_reference(self._tracker, start, counts, [])

    def _from_s_told(self, held: list[tuple[FramePose, Half, bool]]) -> float:
        """The event's bus time: the first sample held's (the tracker's latest without one)."""
        return held[0][1].t_s if held else self._tracker.now_s


def unbounded_why(tracker: PoseTracker) -> str | None:
    """Why the end verdict cannot be a PASS (UNJUDGED): a re-prime declared after a stall
    before the first pose of a power-up not proven, its first pose adopted with nothing to
    bound it by (module docstring); None else."""
    count = tracker.reprime.unbounded
    if not count:
        return None
    return (f"{count} re-prime{'' if count == 1 else 's'} declared after a stall before the "
            "first pose, the power-up not proven (or its frame not heard): the reference started "
            "at the firmware's own pose there, which nothing bounds (an offset not judged)")


def _wrapped(delta: int, bits: int) -> int:
    """A count step read in ``bits``-bit counters (signed)."""
    half = 1 << (bits - 1)
    return (delta + half) % (2 * half) - half
