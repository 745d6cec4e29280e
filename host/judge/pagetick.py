"""Where a rebooted firmware's first count page counts back from when its tick's pose tells it:
the latest encoder frame the firmware had taken when it made the page (``primed.counted_start``:
ENC_E2E_OK + ENC_E2E_LOST - 1 COUNTER steps back from it is the frame it primed on). One rule for
the live judge (``page_after``), the whole-log and replay judges (``pagesent.pages_counted_from``)
and the streamed one (``pagesent.StreamPages``).

Counted from the latest frame heard before the page, a frame can come between the firmware's
mailbox read and its page: restarted under ``tests/test_trial38.py`` on a loaded machine, the
firmware primed on the frame of 3.7403 s and made its page (OK 9, LOST 0) in the tick whose pose
names the frame of 3.8283 s, while the frame of 3.8323 s was heard 0.4 ms before that pose:
counted from it, the life started a frame late and the correct firmware was POSE WRONG by 1.8 mm
and 6.3 mrad (``tests/test_live_page_tick.py`` makes it a lockstep log: every judge 5.68 mm off).

A firmware sends its pose before its summary and page in one tick (firmware/ecu.py step 5), the
pose naming the latest frame it took (ENC_COUNTER). So when the latest ODOM_POSE_X was heard
less than ``TICK_GAP_S`` before the page, and is not behind the pose heard before it (one the bus
held back and let go after later ones names an older frame), the page counts from the frame that
pose names (the latest taken before the pose with its COUNTER, within a lap). Unless the page was
held back (``page_held_back``: its send, ``pagesent``, a cycle before the next pair,
``TICK_GAP_S`` or more before it was heard; its pose is then a later tick's): from its send. The
send's bound is no closer: a loaded firmware's catching-up ticks break it by a few ms (the next
pair 95.7 ms after: counted from 4.3 ms too early, a frame early, 2.4 mm and 15.7 mrad off). In
lockstep, where nothing comes between a tick's reads and its frames, all are the same frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, POSE_COUNTER_LAP

if TYPE_CHECKING:
    from odocan.host.judge.bootnamed import PoseRows
    from odocan.host.judge.tracking import PoseTracker

TICK_GAP_S = 0.005  # a pose and the status pair of one tick are heard less than this apart (s)


def named_after(
    page: tuple[int, float],
    poses: PoseRows,
    taken: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]],
) -> int | None:
    """The log position after the frame the tick's pose of a count page heard at ``page`` (log
    position, bus time) names (``pagesent.counted_from``'s meaning), or None when no pose
    tells it (``pages_named_after`` of one page)."""
    named = int(pages_named_after(np.array([page[0]]), np.array([page[1]]), poses, taken)[0])
    return None if named < 0 else named


def pages_named_after(
    pages: npt.NDArray[np.int64],
    pages_s: npt.NDArray[np.float64],
    poses: PoseRows,
    taken: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]],
) -> npt.NDArray[np.int64]:
    """For count pages heard at log positions ``pages`` and bus times ``pages_s``: the log
    position after the frame each one's tick's pose names (module docstring), -1 where no pose
    tells it; ``poses``: ``bootnamed.pose_enc_rows`` heard (in log order), ``taken``: the
    positions and COUNTERs of the encoder frames the firmware takes, in log order."""
    none = np.full(len(pages), -1, dtype=np.int64)
    if not len(poses[0]) or not len(taken[0]):
        return none
    k = np.searchsorted(poses[0], pages) - 1
    at = np.maximum(k, 0)
    gap_s = pages_s - poses[1][at]
    step = (poses[2][at] - poses[2][np.maximum(at - 1, 0)]) % POSE_COUNTER_LAP
    told = (k >= 0) & (gap_s >= 0.0) & (gap_s < TICK_GAP_S) & (
        (at == 0) | (step < POSE_COUNTER_LAP // 2))
    back = np.searchsorted(taken[0], poses[0][at])[:, None] - np.arange(1, ENC_COUNTER_LAP + 1)
    match = (back >= 0) & (taken[1][np.maximum(back, 0)] == poses[3][at][:, None])
    told &= match.any(axis=1)
    latest = back[np.arange(len(pages)), match.argmax(axis=1)]  # the latest taken first
    return np.where(told, taken[0][np.maximum(latest, 0)] + 1, none)


def page_held_back(page_s: npt.ArrayLike, sent_s: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Whether count pages heard at ``page_s`` and sent at ``sent_s`` or before
    (``pagesent.sent_s``) were held back on the bus: their tick's pose is then another tick's."""
    held: npt.NDArray[np.bool_] = np.asarray(page_s) - np.asarray(sent_s) >= TICK_GAP_S
    return held


def page_after(tracker: PoseTracker) -> tuple[int, int | None]:
    """The window position after the latest frame heard before the count page heard now, and
    after the frame its tick's pose names (None: no pose tells it; module docstring; the
    window holds at least one frame)."""
    window = tracker.window
    seqs = window.col("seq")
    after = int(seqs[-1]) + 1
    page, xs = tracker.status_heard, tracker.pairs.halves["x"]
    if page is None or not len(xs):
        return after, None
    counters = xs.col("counter")
    pose_s = float(xs.col("t_s")[-1])
    step = (int(counters[-1]) - int(counters[-2])) % POSE_COUNTER_LAP if len(xs) > 1 else 0
    if not 0.0 <= page[0] - pose_s < TICK_GAP_S or step >= POSE_COUNTER_LAP // 2:
        return after, None
    named = np.flatnonzero((window.col("t_s") <= pose_s)
                           & (window.col("counter") == xs.col("enc_counter")[-1]))
    return after, (min(after, int(seqs[named[-1]]) + 1) if len(named) else None)
