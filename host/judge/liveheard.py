"""The encoder frames the live judges had heard when a first count page was made
(``sources.SourceWatch.on_page``'s power-up proof, ``livereprime``'s word): up to the frame the
latest pose names, and before a tick's bound. Moved out of ``sources`` (its size), unchanged."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.powerup import NAMED_SPAN

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker


def pose_named_live(tracker: PoseTracker) -> int | None:
    """``powerup.pose_named`` live: the encoder frames heard up to the one the latest pose
    heard names (its ENC_COUNTER: the latest of the last ``NAMED_SPAN`` frames heard before it
    with that COUNTER). None when none."""
    halves = tracker.pairs.halves["x"].rows  # (pos, enc_counter, ...) of the latest X halves heard
    if not halves:
        return None
    pos, named = halves[-1][0], int(halves[-1][1])
    before = [row for row in tracker.window.rows if row[1] < pos][-NAMED_SPAN:]
    seqs = [int(row[0]) for row in before if int(row[2]) == named]
    return seqs[-1] + 1 if seqs else None


def heard_before_live(tracker: PoseTracker, bound_s: float, made: int) -> int | None:
    """``powerup.heard_by_tick`` live: the encoder frames heard before bus time ``bound_s`` and
    among the first ``made``; None when the window no longer holds the frames to tell. The
    whole window (5 s), not its recent rows alone: after an MCU halted at power-up, the page's
    tick bound is seconds back (its ODOM_STATUS COUNTER stood still), as ``analyze`` reads it
    (issue #11: a 3 s halt left the live judges unproven, their start fitted); past the window,
    the watch's first frames kept (``livefirst.FirstStall.heard_first_before``: a 6 s halt)."""
    window = tracker.window
    if not len(window):
        return 0
    before = np.flatnonzero(window.col("t_s") < bound_s)
    if len(before):
        return min(int(window.col("seq")[before[-1]]) + 1, made)
    if int(window.col("seq")[0]) == 0:
        return 0
    return tracker.first.heard_first_before(bound_s, made)  # a stall longer than the window
