"""Resent poses in the live judge (``host.judge.tracking``), as ``analyze`` judges them
(``host.judge.resent``): a pose half naming the encoder frame of the latest sample judged again
(the firmware ticked without a new frame and sent its pose again) is judged with the sample's
other half against the same reference. Its error counts in the largest errors and the loss
allowance's (``LiveAllowance.record``), not as a sample of its own: ``analyze`` puts the worst
pose sent for a frame in its one sample. A resend equal to the sample changes nothing."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.livepose import FramePose, difference
from odocan.host.judge.livewindow import CYCLE_S, Half
from odocan.host.judge.resendalias import aged_past_alias
from odocan.sim.pose import TURN_RAD

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker


def judge_resend(name: str, seq: int, half: Half, tracker: PoseTracker) -> bool:
    """Judge half ``name`` ("x" or "y") naming frame ``seq`` when the latest sample judged is of
    that frame; whether it was (then it is no new sample's half)."""
    last = tracker.last_pair
    if last is None or last[0].seq != seq or may_alias_live(seq, half.t_s, tracker):
        return False
    pose, ref = last
    turns = math.floor(pose.heading_rad / TURN_RAD)  # the sample's TURNS and HEADING
    heading_rad = pose.heading_rad - turns * TURN_RAD
    if name == "x":
        resent = FramePose(seq, half.value, pose.y_m, turns * TURN_RAD + half.extra)
    else:
        resent = FramePose(seq, pose.x_m, half.value, half.extra * TURN_RAD + heading_rad)
    if resent == pose:
        return True
    record_error(tracker, seq, resent, ref, half.t_s)
    return True


def record_error(tracker: PoseTracker, seq: int, pose: FramePose, ref: FramePose,
                 t_s: float) -> None:
    """``pose``'s error from ``ref`` into the tracker's largest errors and its loss allowance's
    record (a half judged outside a sample: a resend, a lone half)."""
    error = difference(pose, ref)
    stats = tracker.vs_reference
    stats.max_dpos_m = max(stats.max_dpos_m, error["dpos_m"])
    stats.max_dheading_rad = max(stats.max_dheading_rad, abs(error["dheading_rad"]))
    tracker.losses.record(seq, error, tracker.fast_path, t_s, shown=False)


def may_alias_live(seq: int, t_s: float, tracker: PoseTracker) -> bool:
    """Whether a half heard at ``t_s`` may name a later frame with frame ``seq``'s COUNTER
    (``host.judge.resendalias.aged_past_alias`` since frame ``seq`` came, or the frame left the
    window)."""
    window = tracker.window
    seqs = window.col("seq")
    k = int(np.searchsorted(seqs, seq))
    if k >= len(seqs) or seqs[k] != seq:
        return True
    return aged_past_alias(t_s - float(window.col("t_s")[k]), CYCLE_S)
