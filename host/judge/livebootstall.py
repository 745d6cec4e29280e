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
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livewindow import silent_since

if TYPE_CHECKING:
    from odocan.host.judge.livestart import Lives
    from odocan.host.judge.tracking import PoseTracker


def left_out_waiting(tracker: PoseTracker, t_s: float, queued: bool,
                     last_s: float | None) -> bool:
    """The module docstring's rule on a sample whose ODOM_POSE_Y came at ``t_s`` (``queued``:
    in a burst; ``last_s``: the previous sample's, or the life's power-up pose's): True when it
    is left out, the placement then owed (``Lives.stalled_waiting``)."""
    lives: Lives = tracker.lives
    if (lives.boot is None or lives.boot[0] < 0 or lives.boot_poses or queued
            or tracker.raw.odometry is not None):
        return False
    if not silent_since(last_s, t_s, tracker.pairs.halves["y"], tracker.window):
        return False
    lives.stalled_waiting = True
    return True
