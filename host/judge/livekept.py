"""What an applied set-pose kept, checked live (issue #11): ``analyze``'s rule
(``host.judge.setposekept.judge_kept``) on the samples and encoder frames the live judge heard.

The live judges (``BusMonitor``, ``RobotTelemetry``) carry the reference across an APPLY that
keeps fields (``livesetpose.apply_set_pose``: the kept fields from the reference at its frame)
and fit its start again within the pose signals' rounding: a firmware that moves a kept field by
a little more than one LSB there can hide in that fit and in the reference's own offset after a
stall's placement (a -1.22 LSB jump 8 ticks after a 150 ms stall was OK live where ``analyze``
FAILs it). So ``KeptWatch`` keeps the latest ``RECENT`` samples of the firmware life, and at such
an APPLY's ACK (``applied``) gathers the ``NARROW_SAMPLES`` + 1 samples after it; then the same
check as ``analyze``'s runs on them (the frames between them from the live window): a jump it
FAILs latches a POSE WRONG episode (``PoseWrongs.jumped``) and is named in the ``set_pose``
event (``kept``, as ``analyze``'s event; ``kept_not_judged``: why not made). A reboot
(``forget``) ends the life: the samples before it are not used, a check still gathering is made
with what it has; a config applied (another geometry or integrator) likewise, the check then
not made (said why).

The APPLY took effect after frame ``c``, the latest encoder frame heard before it on the bus
(``SetPoseFollower``). A set-pose the bridge sent itself is not heard back: when frames came
between its sending and its ACK and a field was staged, where it was set is not known to a frame
(``livesetpose_choice``), and the check is not made (said why); a bare APPLY sets nothing, and
the samples around it continue the same pose wherever it took effect.

An APPLY with no pose before it, in a life whose firmware stalled before its first pose and said
it re-primed on resuming (COUNTER_RESET), is bounded as ``analyze`` bounds it
(``reprimekept``, ``_reprimed``): before, not made, and on a straight drive a firmware that
moved its X by 1 m there was OK (the placement owed after the stall took it in).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from odocan.host.judge.livesetpose import FIELDS
from odocan.host.judge.livewindow import CYCLE_S, window_counts
from odocan.host.judge.reprimekept import from_after, travel, wrapped
from odocan.host.judge.samples import POSITION_LSB_M, Encoders, Poses
from odocan.host.judge.setposekept import NARROW_SAMPLES, NO_START, Kept, Odo, judge_kept
from odocan.host.judge.stallreprime import FIFO_SPAN, R_SPAN

if TYPE_CHECKING:
    from odocan.host.judge.livepose import Sample
    from odocan.host.judge.reference import Geometry
    from odocan.host.judge.tracking import PoseTracker

COARSE_M = 2 * POSITION_LSB_M  # a check wider cannot tell a jump of 2 LSB (report.summary's)
RECENT = NARROW_SAMPLES + 4  # samples kept before an APPLY: the check's, and a stall before them


@dataclass
class _Open:
    """A check gathering the samples around the APPLY after frame ``c`` (tracker seq)."""

    c: int
    staged: dict[str, float]
    event: dict[str, Any]
    samples: list[Sample] = field(default_factory=list)
    why: str | None = None  # not to be made, and why

    def after(self) -> int:
        return sum(1 for s in self.samples if s.pose.seq > self.c)


class KeptWatch:
    """The latest samples of the firmware life, and the checks of APPLYs gathering theirs."""

    def __init__(self) -> None:
        self._recent: deque[Sample] = deque(maxlen=RECENT)
        self._last_seq = -1  # the latest sample's frame (a boot's samples come again: once)
        self._floor: int | None = 0  # samples of frames before it are another life's
        self._open: list[_Open] = []
        self._due: list[_Open] = []  # ended by a reboot: made with what they have
        self.made, self.not_made, self.failed = 0, 0, 0  # checks (the events are a window)
        self.coarse: list[tuple[float, float]] = []  # re-primes' checks passed: (t_s, bound m)
        self._robot: tuple[Geometry, str | None] | None = None  # the samples' robot

    def forget(self) -> None:
        """A reboot the judge saw: the samples heard so far are another firmware life's."""
        self._recent.clear()
        self._floor = None  # the latest frame at the next samples
        self._due += self._open
        self._open = []

    def applied(self, event: dict[str, Any], seq: int, staged: dict[str, float],
                heard_seq: int) -> dict[str, Any]:
        """The ``set_pose`` ``event`` of an APPLY ACKed, which took effect after frame ``seq``
        with ``staged``; ``heard_seq``: the latest frame heard at its ACK. Returns ``event``."""
        if all(name in staged for name in FIELDS):
            return event  # nothing kept: the reference starts exactly at the pose set
        check = _Open(seq, dict(staged), event, list(self._recent))
        if staged and heard_seq > seq:
            check.why = ("the encoder frame the APPLY took effect after not known to a frame "
                         "(frames heard between it and its ACK) and a field staged")
        self._open.append(check)
        return event

    def heard(self, tracker: PoseTracker, samples: list[Sample]) -> list[Sample]:
        """The samples ``tracker`` settled (``take_samples``), returned: kept, and a check
        made once it has ``NARROW_SAMPLES`` + 1 samples after its APPLY."""
        if self._floor is None:
            self._floor = tracker.enc_seq
        robot, kept = (tracker.geometry, tracker.integrator), self._robot
        # the robot kept as heard last: an equal Geometry made again (each PROFILE page's speed
        # bound, ``PoseTracker.take_speed_bound``) compared once, then by identity (per sample)
        self._robot = robot
        if robot != kept:  # a config applied
            self._recent.clear()
            for check in self._open:
                check.why = "a config applied between the poses around the APPLY"
            self._due += self._open
            self._open = []
        for sample in samples:
            seq = sample.pose.seq
            if seq <= self._last_seq or seq < self._floor:
                continue
            self._last_seq = seq
            self._recent.append(sample)
            for check in self._open:
                check.samples.append(sample)
        for check in [c for c in self._open if c.after() > NARROW_SAMPLES]:
            self._open.remove(check)
            self._due.append(check)
        due, self._due = self._due, []
        for check in due:
            self._counted(check, _made(tracker, check), tracker)
        return samples

    def _counted(self, check: _Open, kept: Kept, tracker: PoseTracker) -> None:
        """The check made (``kept``): into its event, counted; a re-prime's coarse one kept
        (``coarse_why``)."""
        _mark(tracker, check, kept)
        if not isinstance(kept, dict):
            self.not_made += 1
            return
        self.made, self.failed = self.made + 1, self.failed + (not kept["passed"])
        if kept["passed"] and kept.get("reprimed") and kept["bound_m"] > COARSE_M:
            self.coarse.append((float(check.event["t_s"]), float(kept["bound_m"])))


def coarse_why(kept: KeptWatch) -> str | None:
    """Why the end verdict cannot be a PASS (UNJUDGED): a bare APPLY after a re-prime whose
    check (``_reprimed``) holds only within a bound wider than ``COARSE_M``, a jump within it
    not told from the frames the firmware may have taken; None else."""
    if not kept.coarse:
        return None
    t_s, bound_m = kept.coarse[-1]
    return (f"what the ODOM_SET_POSE APPLY at {t_s:.3f} s kept judged only within "
            f"{bound_m * 1e3:.4g} mm (the firmware re-primed after a stall before its first "
            f"pose: which frames it took is not known; {len(kept.coarse)} such APPLY)")


def _made(tracker: PoseTracker, check: _Open) -> Kept:
    """``judge_kept`` on the samples ``check`` gathered and the window's frames between them."""
    if check.why is not None:
        return check.why
    if tracker.integrator is None:
        return "the firmware's integrator not known"
    before = [s for s in check.samples if s.pose.seq <= check.c][-(NARROW_SAMPLES + 4):]
    after = [s for s in check.samples if s.pose.seq > check.c][:NARROW_SAMPLES + 1]
    used = before + after
    first = used[0].pose.seq if used else check.c
    frames = [f for f in window_counts(tracker.window, first) if f[0] <= max(
        check.c, used[-1].pose.seq if used else check.c)]
    if not frames or frames[0][0] != first:
        return "the encoder frames around the APPLY left the live window"
    seqs = np.array([f[0] for f in frames])
    periods = np.array([f[4] for f in frames])
    periods[0] = 0
    enc = Encoders(index=seqs - first, counter=np.array([f[1] for f in frames]),
                   seq=np.cumsum(periods), left=np.array([f[2] for f in frames]),
                   right=np.array([f[3] for f in frames]),
                   timestamp_s=np.array([f[6] for f in frames], dtype=float), cycle_s=CYCLE_S,
                   twinned=np.array([tracker.twins.twinned(int(s)) for s in seqs]),
                   uptime=np.array([f[5] for f in frames]))
    poses = Poses(enc=np.array([s.pose.seq - first for s in used], dtype=np.int64),
                  x_m=np.array([s.pose.x_m for s in used]),
                  y_m=np.array([s.pose.y_m for s in used]),
                  heading_rad=np.array([s.pose.heading_rad for s in used]),
                  heading_raw=np.zeros(len(used), dtype=np.int64))
    odo = Odo(tracker.geometry, tracker.counter_bits, tracker.integrator, "profile")
    sent_s = np.array([s.t_s for s in used], dtype=float)
    kept = judge_kept((poses, enc, sent_s), check.c - first, check.staged, odo)
    return _reprimed(tracker, check, odo) if kept == NO_START and after else kept


def _reprimed(tracker: PoseTracker, check: _Open, odo: Odo) -> Kept:
    """``reprimekept``'s check live: an APPLY with no pose before it in a life whose firmware
    stalled before its first pose (``livefirst``: ``stalled_from``, the first frame it could
    have primed on) and said it re-primed on resuming (``ReprimeHold.word``). The frames it
    can have integrated: its FIFO's (``FIFO_SPAN`` from ``stalled_from``; at the speed bound
    when the window no longer holds them) and those from ``R_SPAN`` before its first sample
    after the stall to the APPLY's; the sample after the APPLY moved back by the steps since."""
    primed, (first_seq, said) = tracker.first.stalled_from, tracker.reprime.word()
    after = next(s for s in check.samples if s.pose.seq > check.c)
    if primed is None or not said or not primed < first_seq <= after.pose.seq:
        return NO_START
    r_min = max(primed, first_seq - R_SPAN)
    rows = [f for f in window_counts(tracker.window, r_min) if f[0] <= after.pose.seq]
    if not rows or rows[0][0] != r_min or any(f[4] != 1 for f in rows[1:]):
        return "the firmware re-primed after a stall; the frames since not all in the window"
    d_left = wrapped(np.diff([f[2] for f in rows]), odo.bits)
    d_right = wrapped(np.diff([f[3] for f in rows]), odo.bits)
    c = check.c - r_min
    reach_m, reach_rad = travel(d_left[:c], d_right[:c], odo.geometry)
    fifo = [f for f in window_counts(tracker.window, primed) if f[0] <= primed + FIFO_SPAN]
    if len(fifo) == FIFO_SPAN + 1 and fifo[0][0] == primed:  # the FIFO's frames heard
        fifo_m, fifo_rad = travel(wrapped(np.diff([f[2] for f in fifo]), odo.bits),
                                  wrapped(np.diff([f[3] for f in fifo]), odo.bits), odo.geometry)
    else:  # at the speed bound
        bound = tracker.raw.gate.bound
        fifo_m, fifo_rad = travel(np.full(FIFO_SPAN, bound[0]), np.full(FIFO_SPAN, bound[1]),
                                  odo.geometry)
        fifo_rad = 2.0 * fifo_m / odo.geometry.wheelbase_m  # the wheels opposite
    pose = after.pose
    return from_after((pose.x_m, pose.y_m, pose.heading_rad), (d_left[c:], d_right[c:]),
                      (reach_m + fifo_m, reach_rad + fifo_rad), check.staged, odo)


def _mark(tracker: PoseTracker, check: _Open, kept: Kept) -> None:
    """The check into its ``set_pose`` event (``analyze``'s ``kept``, ``kept_not_judged``); a
    failed one latches a POSE WRONG episode at the first sample after the APPLY."""
    event = check.event
    if isinstance(kept, str) or kept is None:
        event["kept"], event["kept_not_judged"] = None, kept
        return
    event["kept"] = kept
    if kept["passed"]:
        return
    first = next(s for s in check.samples if s.pose.seq > check.c)
    tracker.wrongs.jumped(first.pose.seq, first.t_s, kept["position_jump_m"],
                          kept["heading_jump_rad"])
    event["detail"] += (f"; POSE WRONG: the firmware's pose jumped {kept['position_jump_m']:.6f} m,"
                        f" {kept['heading_jump_rad']:.6f} rad at an APPLY that kept "
                        f"{', '.join(kept['fields_kept'])}")
