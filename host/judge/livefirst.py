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
frames heard before its tick bound, long gone from the window (``sources.heard_before_live``;
issue #11: a 6 s halt at power-up left the live judges unproven, their start adopted)."""

from __future__ import annotations

import bisect
from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.livewindow import window_encoders
from odocan.host.judge.stalls import first_after_stall

if TYPE_CHECKING:
    from odocan.host.judge.livepose import FramePose
    from odocan.host.judge.tracking import PoseTracker

FIRST_FRAMES = 128  # the watch's first encoder frames whose bus times are kept (1.28 s at 100 Hz)
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

    def keep_first(self, times_s: tuple[float, ...]) -> None:
        """The bus times of the watch's first ``FIRST_FRAMES`` encoder frames (seq 0 on)."""
        self.first_times_s = times_s

    def heard_first_before(self, bound_s: float, made: int) -> int | None:
        """How many of the watch's first frames were heard before ``bound_s``, at most ``made``;
        None when the frames kept cannot tell (none kept, or all heard before it)."""
        times = self.first_times_s
        if not times or times[-1] < bound_s:
            return None
        return min(bisect.bisect_left(times, bound_s), made)

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
        alive_s = np.sort(np.concatenate(([talked[0]], sent_s)))
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
    if (tracker.raw.odometry is None and lives.power_up_proven and lives.boot is None
            and not tracker.reference_starts and tracker.integrator is not None):
        lives.finish_boot(0, first_life=True)  # from (0, 0, 0) on frame 0, as analyze
    tracker.first.stalled_from = primed  # (``LiveDistance``: its merged step's allowance)
    if tracker.raw.odometry is not None:
        rule.owe_from(primed)  # placed at the next sample, bounded from that frame
        tracker.losses.stalled_first(primed)  # the frames between: the placement's, no loss's
    rule.heard_first(t_s)
    return True
