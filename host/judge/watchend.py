"""The end of a live watch (``odocan monitor``, ``odocan bridge``, ``odocan fleet``): what the
live judges still wait with is judged, as the whole-log judge judges a log's tail (issue #11,
one judge; rule 5: a PASS never hides a wrong pose, nor a wrong DISTANCE).

The frames a hold kept are the caller's to release first (the monitor's ``release_held``, the
bridge's ``BridgeHold.release(ends=True)``); then ``end_watch``: the pose halves not settled
yet, paired or judged alone (``livehalves.HalfPairs.end``: a log ending on a pose never
judged it live), the last pages' proof and the
choices held (``livegapseen.end_of_watch``), the ODOM_TWIST DISTANCE samples still waiting for
the page after their frame (``LiveDistance.finish``: before, never judged, so a DISTANCE wrong
in the watch's last 0.6-1.8 s passed), and the pose samples still waiting for a later page
(``posewrongs.PoseWrongs.finish``). The twist speeds wait for nothing (``livetwist`` judges a
sample when it comes).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livegapseen import end_of_watch

if TYPE_CHECKING:
    from odocan.host.judge.livedistance import LiveDistance
    from odocan.host.judge.tracking import PoseTracker


def end_watch(tracker: PoseTracker, distance: LiveDistance) -> None:
    """The watch ends, no later frame comes: everything still waiting judged (module
    docstring)."""
    tracker.pairs.end()  # the last pose's halves settled, paired or judged alone (livehalves)
    end_of_watch(tracker)
    distance.finish(tracker)
    tracker.wrongs.finish(tracker.allowance_m)
