"""Where a rebooted firmware's first count page counts back from, live: the latest encoder frame
the firmware had taken when it made the page (``primed.counted_start``: ENC_E2E_OK +
ENC_E2E_LOST - 1 COUNTER steps back from it is the frame it primed on).

The live judge took the latest frame heard before the page. On a real-time bus a frame can reach
the watch after the firmware's tick read its mailbox but before that tick's frames: restarted
under ``tests/test_trial38.py`` on a loaded machine, the firmware primed on the frame of 3.7403 s
and made its page (OK 9, LOST 0) in the tick whose pose names the frame of 3.8283 s, while the
frame of 3.8323 s was heard 0.4 ms before that pose: counted from it, the life started a frame
late and the correct firmware was POSE WRONG by 1.8 mm and 6.3 mrad.

A firmware sends its pose before its summary and page in one tick (firmware/ecu.py step 5), the
pose naming the latest frame it took (ENC_COUNTER). So when the latest ODOM_POSE_X was heard
less than ``TICK_GAP_S`` before the page's summary, the page counts from the frame that pose
names (the latest heard before the pose with its COUNTER), when that is earlier; and not moved
again by the page's send time (``pagesent``: a cycle before the next pair), which a loaded
firmware's catching-up ticks break (the next pair 95.7 ms after: counted from 4.3 ms too early,
a frame early, 2.4 mm and 15.7 mrad off). In lockstep, where nothing comes between a tick's
reads and its frames, both are the same frame.
The whole-log and streamed judges still count from the latest frame stamped before the page
(``pagesent``): the same race is theirs too (issue #11, left).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

TICK_GAP_S = 0.005  # a pose and the summary of one tick are heard less than this apart (s)


def page_after(tracker: PoseTracker) -> tuple[int, bool]:
    """The window position after the latest frame a count page heard now counts back from
    (module docstring; the window holds at least one frame), and whether its tick's pose told
    it."""
    window = tracker.window
    seqs = window.col("seq")
    after = int(seqs[-1]) + 1
    summary, xs = tracker.status_heard, tracker.pairs.halves["x"]
    if summary is None or not len(xs):
        return after, False
    pose_s = float(xs.col("t_s")[-1])
    if not 0.0 <= summary[0] - pose_s < TICK_GAP_S:
        return after, False
    named = np.flatnonzero((window.col("t_s") <= pose_s)
                           & (window.col("counter") == xs.col("enc_counter")[-1]))
    return (min(after, int(seqs[named[-1]]) + 1), True) if len(named) else (after, False)
