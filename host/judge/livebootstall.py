"""A new firmware that halted after its first tick, told live (issue #11, rule 5: a FAIL must
never blame a correct firmware): ``stalls.after_stalls``' silence while a rebooted life's
samples wait for the frame it primed on (``livestart.Lives.boot``).

The stall rule (``livestall``) acts once the reference runs; a reboot's samples wait for the
count page that names the life's start, so a silence before the first of them passed unseen.
pmir random 5, ``reboot=5:0.1,stall=5.11:0.4``: the new firmware sent its power-up pose at
5.101 s, halted 0.4 s, its mailbox dropped 44 frames (ENC_E2E_LOST 12: two COUNTER laps
hidden) and it took the backlog's steps as one. Its first sample after the halt names a backlog
frame, which ENC_COUNTER cannot resolve, and the next ones a position the fine reference left:
POSE WRONG, 0.5243 mm for an allowance of 12 frames' 0.1243 mm, where ``analyze`` re-places
the position after the stall (0.5271 mm absorbed within 1.041 mm allowed) and PASSes.

Now the first sample whose ODOM_POSE_Y came ``SILENCE_CYCLES`` cycles or more after the
firmware last talked, with encoder frames on time meanwhile (``livewindow.silent_since``), when
no sample of the life waits yet, is left out, and once the start is known the position is
placed again at the next sample, bounded from that start (``livestart.start_reference``'s
``stalled_from``, as ``livefirst`` owes it after a stall before the first life's first sample).

The new life's power-up pose (0, 0, 0) may wait before it, heard after the boot summary: it is
no step of the firmware's, the rule holds over it, and the placement is at the first sample
after it (pmir random 5, 7 s, ``reboot=2.5:0.05,stall=2.56:0.3``, with or without
``delay=0.2:30``: the first sample after the 0.3 s halt judged, the position 2.02 mm off for an
allowance of 0.26 mm, POSE WRONG 1.84 mm beyond; pmir random 1: 0.33 mm). With the delay the
samples right after the halt may name frames the host's E2E check refused (held back): the first
compared comes after them: the silence is the one up to the first ODOM_POSE_Y after the power-up
pose, or after the boot summary when that pose was not compared either (random 5: 2.45 mm
beyond, kobuki 2.99 mm; random 6, its power-up pose held back: 1.22 mm, kobuki 1.68 mm).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.livebootbound import power_up_pose
from odocan.host.judge.livestart import BOOT_COUNT_WAIT_S
from odocan.host.judge.livewindow import silent_since

if TYPE_CHECKING:
    from odocan.host.judge.livestart import Lives
    from odocan.host.judge.tracking import PoseTracker


def left_out_waiting(tracker: PoseTracker, t_s: float, queued: bool,
                     last_s: float | None) -> bool:
    """The module docstring's rule on a sample whose ODOM_POSE_Y came at ``t_s`` (``queued``:
    in a burst; ``last_s``: the previous sample's, or the life's power-up pose's): True when it
    is left out, the placement then owed (``Lives.stalled_waiting``). The life's power-up pose
    waiting is no sample of its integration (``power_up_pose``); the silence is the one up to the
    first ODOM_POSE_Y after ``last_s`` (None: after the boot summary), the samples after the
    halt before this one not compared (they named frames the host's E2E check refused)."""
    lives: Lives = tracker.lives
    if (lives.boot is None or lives.boot[0] < 0 or queued or tracker.raw.odometry is not None
            or not all(map(power_up_pose, lives.boot_poses))):
        return False
    ys = tracker.pairs.halves["y"]
    since_s = lives.boot[1] - BOOT_COUNT_WAIT_S if last_s is None else last_s
    sent_s = ys.col("t_s") if len(ys) else np.zeros(0)
    after = sent_s[sent_s > since_s]  # the first ODOM_POSE_Y since: those between may name none
    if not len(after) or not silent_since(since_s, min(t_s, float(after[0])), ys, tracker.window):
        return False
    lives.stalled_waiting = True
    return True
