"""A stall before a life's first pose, told live (issue #11): ``stalls.first_after_stall``, the
whole log's rule, at the first sample since the live stall rule started (``livestall``).

A firmware SIGSTOPped while INIT (it had sent only its ODOM_STATUS) and resumed after the sim
drove on primes on the first frame its receive FIFO kept, steps the next ones it kept, refuses
the rest and takes the frame it resumes at as one step: its first pose names a frame of its
backlog, which ENC_COUNTER cannot resolve, and its next ones a position the fine reference left.
So the first sample whose ODOM_POSE_Y came ``SILENCE_CYCLES`` cycles or more after the
firmware's last frame (its ODOM_STATUS, ``PoseTracker.on_status``, or a pose half), with the encoder
frames on time meanwhile, is left out; when the reference runs from the firmware's power-up
(a proven power-up at frame 0: ``Lives.power_up_proven``), the position is placed again at the
next sample, bounded by the merge allowance from the first frame the firmware could have primed
on (``liveplace.StallPlacer.shift``), as ``analyze`` restarts its segment there (also when the
proof comes after this sample, while the life's next samples wait for its count page: the
frame kept in ``stalled_from``, ``livestart.start_reference``; issue #11's 3 s halt at power-up
in the rig); else the next sample starts the reference (fitted), as ``analyze`` starts it at
its first sample kept. The
frames between that frame and the placed sample's are the placement's: the firmware's
ENC_E2E_LOST counts the frames its FIFO overran among them, which open no loss allowance on top
(``livelosses.LiveAllowance.stalled_first``, ``losses.placement_accounted``).

``LiveDistance`` leaves the first ODOM_TWIST after such a silence out by the same times
(``talked_before``: ``distance.DistanceJudge.talked_before``'s rule).

The watch's first ``FIRST_FRAMES`` encoder frames' bus times are kept (``keep_first``): a
power-up's first count page, made after a stall longer than the window (5 s), is proven by the
frames heard before its tick bound, long gone from the window (``liveheard.heard_before_live``;
issue #11: a 6 s halt at power-up left the live judges unproven, their start adopted), and their
counts (``stallpowerup``'s rule below).

A power-up proven by the stall itself (``host.judge.stallpowerup``, the whole log's rule): when
the firmware's first count pages are lost, the first sample after a stall at the watch's start
proves the power-up at frame 0 (``Lives.power_up_proven``, then as the page's proof) when the
first ODOM_STATUS heard is of its first cycle, its first summary says UPTIME 0, every summary
up to the stall says INIT, no pose half came before it, and frames 0 .. the one it could first
have primed on carry the same counts (whichever it primed on, the same start). The firmware
stalled after such a power-up over a moving robot: not proven, and the start the judges take
then (the firmware's pose) is said adopted (``UNPROVEN``: the end verdicts UNJUDGED, never a
PASS that hides its first pose)."""

from __future__ import annotations

import bisect
from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np

from odocan.host.judge.livewindow import QUEUED_GAP_S, window_encoders
from odocan.host.judge.powerup import holds_first_cycle
from odocan.host.judge.stallpowerup import INIT, UNPROVEN
from odocan.host.judge.stalls import first_after_stall
from odocan.host.protocol import busfacts
from odocan.host.protocol.dbcplan import default_plan

if TYPE_CHECKING:
    from odocan.host.judge.livepose import FramePose
    from odocan.host.judge.tracking import PoseTracker

FIRST_FRAMES = 128  # the watch's first encoder frames whose bus times are kept (1.28 s at 100 Hz)
_STATE = default_plan().get_message_by_name("ODOM_STATUS").get_signal_by_name("STATE")
INIT_CODES = frozenset(int(v) for v, n in (_STATE.choices or {}).items() if str(n) == INIT)
STATUS_KEPT = 8  # the latest ODOM_STATUS frames kept (up to 3 a tick): a sample settles
# within a cycle of its Y, so the last one before it is among them


class FirstStall:
    """The firmware's latest ODOM_STATUS frames (bus time, encoder frames heard before) and the
    rule on a life's first sample (module docstring)."""

    def __init__(self) -> None:
        # its ODOM_STATUS frames: bus time, encoder frames heard before (``on_status`` appends)
        self.alive: deque[tuple[float, int]] = deque(maxlen=STATUS_KEPT)
        self.stalled_from: int | None = None  # the frame of the latest stall told (primed)
        self.first_times_s: tuple[float, ...] = ()  # the watch's first frames' bus times (s)
        self.first_counts: tuple[tuple[int, int], ...] = ()  # ... and their LEFT, RIGHT counts
        self.init_s: float | None = None  # the first summary's bus time, while it says INIT at
        self.broke_s: float | None = None  # UPTIME 0; the first ODOM_STATUS that said otherwise
        self.posed_s: float | None = None  # the first pose half's bus time
        self.unproven = False  # its power-up stalled over a moving robot (``unproven_why``)
        self.told_s: tuple[float, ...] = ()  # a told-ahead life's frames before it was told
        # a halted tick's ODOM_STATUS frames sent after the halt (``halted_sent``): bus times,
        # and the latest's bus time and COUNTER (the next of its burst follows it)
        self.sent_late: deque[float] = deque(maxlen=STATUS_KEPT)
        self._late: tuple[float, int] | None = None

    def keep_first(self, times_s: tuple[float, ...],
                   counts: tuple[tuple[int, int], ...] = ()) -> None:
        """The bus times of the watch's first ``FIRST_FRAMES`` encoder frames (seq 0 on) and
        their counts."""
        self.first_times_s, self.first_counts = times_s, counts

    def on_status(self, t_s: float, signals: dict[str, Any] | None) -> None:
        """An accepted ODOM_STATUS (raw ``signals``, None: not told) at bus time ``t_s``: does
        the firmware still say it primed on nothing since its power-up (``stallpowerup``)?"""
        if self.broke_s is not None:
            return
        first = self.init_s is None and not self.alive
        if signals is None or (first and not holds_first_cycle(int(signals["COUNTER"]))):
            self.broke_s = t_s
        elif int(signals.get("PAGE", -1)) == busfacts.SUMMARY_PAGE:
            init = int(signals["STATE"]) in INIT_CODES
            if not init or (self.init_s is None and int(signals["UPTIME"]) != 0):
                self.broke_s = t_s
            elif self.init_s is None:
                self.init_s = t_s

    def powered_up(self, tracker: PoseTracker, t_s: float) -> bool | None:
        """``stallpowerup.stalled_power_up`` live, for the first sample (its ODOM_POSE_Y at
        ``t_s``) after a stall: True when proven, None when its power-up stalled but the robot
        moved (or the frames are no longer kept), False when no such power-up. The frames it
        may have primed on: those up to the first heard after its last ODOM_STATUS (counted
        by that status, not from the window: a stall longer than it)."""
        talked = self.talked_before(t_s)
        if (talked is None or self.init_s is None or self.init_s > talked[0]
                or (self.broke_s is not None and self.broke_s <= talked[0])
                or (self.posed_s is not None and self.posed_s <= talked[0])):
            return False  # (no pose half before it: the stall is from that status)
        counts = self._counts(tracker, talked[1])
        if counts is None:
            return None
        return all(c == counts[0] for c in counts) or None

    def proven_after_all(self, tracker: PoseTracker) -> None:
        """The first life's reference started at (0, 0, 0) on frame 0 after all (its first
        count page proved it, ``livestart.Lives.finish_boot``): its first pose judged, no
        longer unproven nor adopted."""
        if self.unproven:
            self.unproven = False
            adopted = tracker.adopted
            adopted.life = [a for a in adopted.life if a.cause != UNPROVEN]

    def _counts(self, tracker: PoseTracker, upto: int) -> list[tuple[int, int]] | None:
        """The LEFT, RIGHT counts of frames 0 .. ``upto`` (seq), None when not kept."""
        window = tracker.window
        if len(window) and int(window.col("seq")[0]) == 0 and upto < len(window):
            return list(zip(window.col("left")[: upto + 1].tolist(),
                            window.col("right")[: upto + 1].tolist(), strict=True))
        kept = self.first_counts
        return list(kept[: upto + 1]) if upto < len(kept) else None

    def heard_first_before(self, bound_s: float, made: int) -> int | None:
        """How many of the watch's first frames were heard before ``bound_s``, at most ``made``;
        None when the frames kept cannot tell (none kept, or all heard before it)."""
        times = self.first_times_s
        if not times or times[-1] < bound_s:
            return None
        return min(bisect.bisect_left(times, bound_s), made)

    def told(self, heard_s: list[float]) -> None:
        """A reboot told by the first pose after its summary (``sources.SourceWatch.take_ahead``):
        the bus times of that summary and of the frames its firmware sent since (poses,
        ODOM_STATUS, whatever their E2E sequence: refused until the reboot was told). Its first
        sample comes after them: no stall (issue #11: a reset at tick 10, its first pose pair
        lost, read as a stall; the position placed at a wrong firmware's pose, 1 LSB PASSed)."""
        self.told_s = tuple(heard_s)

    def talked(self, t_s: float, heard: int, counter: int | None) -> None:
        """An accepted ODOM_STATUS at bus time ``t_s`` (``heard``: the encoder frames heard
        before it; ``counter``: its E2E COUNTER, None: not told): kept in ``alive``; the next
        frame of a halted tick's burst (``halted_sent``: its COUNTER the next, less than
        ``QUEUED_GAP_S`` after) kept as sent late too."""
        self.alive.append((t_s, heard))
        late = self._late
        if (late is not None and counter is not None and 0 < t_s - late[0] < QUEUED_GAP_S
                and counter == (late[1] + 1) % busfacts.STATUS_COUNTER_LAP):
            self._late = (t_s, counter)
            self.sent_late.append(t_s)

    def halted_sent(self, t_s: float, counter: int | None) -> None:
        """The summary heard at bus time ``t_s`` (E2E ``counter``) was made before its
        firmware halted and sent after (``haltedsend``, told by ``sources.SourceWatch``): it
        and the rest of its tick's burst say nothing of when the firmware last talked
        (``made_before``)."""
        self.sent_late.append(t_s)
        self._late = None if counter is None else (t_s, counter)

    def made_before(self, t_s: float) -> tuple[float, int] | None:
        """``talked_before`` of the ODOM_STATUS frames made when sent: a halted tick's sent
        after the halt left out (``halted_sent``). A stall's silence is measured from it
        (``livereprime``, as ``stallreprime.around`` takes the summaries around the stall:
        issue #11, kobuki halted 2 s mid-tick, its summary 2 s late read as talk 1 ms before
        the stall's first sample: the re-prime it declared was missed, POSE WRONG 184.6 mm
        on the correct firmware)."""
        late = self.sent_late
        before = [frame for frame in self.alive if frame[0] < t_s and frame[0] not in late]
        return before[-1] if before else None

    def talked_before(self, t_s: float) -> tuple[float, int] | None:
        """The latest ODOM_STATUS before bus time ``t_s`` (its time, the frames heard before),
        None when none is kept."""
        before = [frame for frame in self.alive if frame[0] < t_s]
        return before[-1] if before else None

    def primed(self, tracker: PoseTracker, t_s: float) -> int | None:
        """``stalls.first_after_stall`` over the tracker's window for a sample whose
        ODOM_POSE_Y came at ``t_s``: the encoder frame (seq) the firmware could first have
        primed on after a silence, None when it was not silent."""
        talked = self.talked_before(t_s)
        if talked is None or not len(tracker.window):
            return None
        ys = tracker.pairs.halves["y"]  # the pose halves sent before it are alive too
        sent_s = ys.col("t_s") if len(ys) else np.zeros(0)
        alive_s = np.sort(np.concatenate(([talked[0]], sent_s, self.told_s)))
        at = first_after_stall(t_s, window_encoders(tracker.window), alive_s)
        return None if at is None else int(tracker.window.col("seq")[at])


def left_out_first(tracker: PoseTracker, pose: FramePose, t_s: float, queued: bool) -> bool:
    """The module docstring's rule on the sample ``pose`` (its ODOM_POSE_Y at ``t_s``,
    ``queued``: in a burst): True when it is left out. Only the first sample since the stall
    rule started (``livestall.StallRule.last_t_s`` None, no silence carried into it)."""
    rule = tracker.stall
    if rule.last_t_s is not None or rule.carried or queued:
        return False
    primed = tracker.first.primed(tracker, t_s)
    if primed is None:
        return False
    lives = tracker.lives
    if (tracker.raw.odometry is None and not lives.power_up_proven and lives.boot is None
            and not tracker.reference_starts):  # the first life's power-up, its pages lost
        proven = tracker.first.powered_up(tracker, t_s)
        lives.power_up_proven = proven is True
        if proven is None:  # the start the judges take: the firmware's own pose
            tracker.adopted.owe(UNPROVEN)
            tracker.first.unproven = True
    if (tracker.raw.odometry is None and lives.power_up_proven and lives.boot is None
            and not tracker.reference_starts and tracker.integrator is not None):
        lives.finish_boot(0, first_life=True)  # from (0, 0, 0) on frame 0, as analyze
    tracker.first.stalled_from = primed  # (``LiveDistance``: its merged step's allowance)
    if lives.boot is not None and lives.boot[0] >= 0 and not lives.boot_poses:
        lives.stalled_waiting = True  # a reboot's, placed at its start (``livebootstall``)
    if tracker.raw.odometry is not None:
        rule.owe_from(primed)  # placed at the next sample, bounded from that frame
        tracker.losses.stalled_first(primed)  # the frames between: the placement's, no loss's
    rule.heard_first(t_s)
    return True


def unproven_why(tracker: PoseTracker) -> str | None:
    """Why the end verdict cannot be a PASS (UNJUDGED): the first life's power-up stalled over
    a moving robot, its first pose adopted unproven (module docstring); None else."""
    return f"{UNPROVEN} (an offset there not judged)" if tracker.first.unproven else None
