"""Which encoder frame a set-pose the bridge sent took effect after (``host.judge.livesetpose``).

A frame the bridge sends itself is not heard back: ``SetPoseFollower`` notes, when the bridge
sends the APPLY, the latest encoder frame the bridge has heard (N). On a live bus the bridge's
reader lags the bus: an encoder frame can already be on the bus, ahead of the APPLY, and not yet
heard; the firmware then drains it first and applies the pose after it. Found in a harness: the
reference, restarted at the set pose at N, stayed one step ahead of a correct firmware (≈4 mm,
an open POSE WRONG episode, for good).

The bus order fixes the frame to a few: the firmware applied the pose after a frame M the bus
carried before the APPLY (so N <= M) and ACKs the APPLY after draining it (so M <= L, the latest
encoder frame heard when the ACK is). When L > N, ``ApplyChoice`` keeps the reference
restarted at N and, at the firmware's first ODOM_POSE_X naming frame L or later, takes the
candidate M in [N, L] whose pose there (the set pose moved by the reference's own steps from M
on) is nearest the on-board one, and restarts the reference at M when it is not N. The choice is
between the orders the bus may have had, nothing more: a firmware that set another pose, or
stepped wrongly, is as far from every candidate and is judged wrong.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from odocan.host.judge.livesetpose import FIELDS, apply_set_pose
from odocan.host.judge.livewindow import window_counts

if TYPE_CHECKING:
    from odocan.host.judge.livepose import FramePose
    from odocan.host.judge.tracking import PoseTracker

_TURN = 2.0 * math.pi


class ApplyChoice:
    """A set-pose applied after frame N, N..L possible (see the module docstring)."""

    def __init__(self, staged: dict[str, float], first_seq: int, last_seq: int,
                 event: dict[str, Any]) -> None:
        self.staged = staged
        self.first_seq, self.last_seq = first_seq, last_seq
        self.event = event  # the ``set_pose`` event: its ``encoder_frame`` follows the choice

    @classmethod
    def after_ack(cls, tracker: PoseTracker, seq: int, staged: dict[str, float],
                  event: dict[str, Any]) -> ApplyChoice | None:
        """The choice owed after ``apply_set_pose(tracker, seq, staged)``, None when the frame is
        certain (no encoder frame heard since the APPLY was sent), or when the pose is not all
        staged (the fields kept come from the reference) or not started at ``seq``."""
        if tracker.enc_seq <= seq or any(name not in staged for name in FIELDS):
            return None
        if event.get("encoder_frame") != seq:
            return None
        return cls(dict(staged), seq, tracker.enc_seq, event)

    def on_pose_x(self, tracker: PoseTracker, enc_counter: int, x_m: float,
                  heading_rad: float) -> bool:
        """An ODOM_POSE_X heard (before the tracker takes it): True once the choice is made (or
        can no longer be: the frames left the window)."""
        counts = window_counts(tracker.window, self.first_seq)
        named = [c[0] for c in counts if c[1] == enc_counter and self.last_seq <= c[0]]
        if not counts or counts[0][0] != self.first_seq:
            return True  # out of the window: keep N
        if not named:
            return False  # a pose of a frame before L: wait
        at = named[0]
        best = min(range(self.first_seq, self.last_seq + 1),
                   key=lambda m: _distance(self._candidate(tracker, m, at), x_m, heading_rad))
        if best != self.first_seq and apply_set_pose(tracker, best, self.staged) is not None:
            self.event["encoder_frame"] = best
        return True

    def _candidate(self, tracker: PoseTracker, m: int, at: int) -> tuple[float, float] | None:
        """(x m, heading rad) at frame ``at`` had the pose been set after frame ``m``: the set
        pose moved by the reference's steps from ``m`` to ``at`` (a rigid motion: the same from
        any start); None when the reference lacks them."""
        start, end = tracker.raw.at.get(m), tracker.raw.at.get(at)
        if start is None or end is None:
            return None
        return _moved(start, end, self.staged)


def _moved(start: FramePose, end: FramePose, staged: dict[str, float]) -> tuple[float, float]:
    """``staged``'s pose moved by the motion from ``start`` to ``end`` (x m, heading rad)."""
    dx, dy = end.x_m - start.x_m, end.y_m - start.y_m
    turn = staged["HEADING"] - start.heading_rad  # the set frame relative to the reference's
    x_m = staged["X"] + dx * math.cos(turn) - dy * math.sin(turn)
    return x_m, staged["HEADING"] + end.heading_rad - start.heading_rad


def _distance(candidate: tuple[float, float] | None, x_m: float, heading_rad: float) -> float:
    """How far ``candidate`` is from the on-board X and HEADING (m plus rad)."""
    if candidate is None:
        return math.inf
    dheading = (candidate[1] - heading_rad + math.pi) % _TURN - math.pi
    return abs(candidate[0] - x_m) + abs(dheading)
