"""The segments a fitted reference start is placed on (``reference_path._start_pose``): the
reference's own and one more after the first frame of each loss span of the firmware (issue
#11, rule 5: a FAIL must never blame a correct firmware)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

IntArray = npt.NDArray[np.int64]


def fit_segments(starts: npt.NDArray[np.bool_], lossy: Sequence[int], e0: int) -> IntArray:
    """The segments of a fitted start (``reference_path._start_pose``): the reference's
    (``starts``: where its position restarts, from frame ``e0``) and a new one after the first
    frame of each loss span (``lossy``). A mailbox overflow merges steps the firmware never saw
    (a sender's backlog let out in a flood: 3.5 mm on a circle), and its position is off by
    that merge from there on (a constant offset: the heading stays exact); fitted as if it were
    not, the start's rotation leaned towards it, and a correct firmware was 0.17 mm off before
    the flood (a 3 s SIGSTOP of the simulator, Python firmware)."""
    split = starts.copy()
    inside = np.asarray(lossy, dtype=np.int64) + 1 - e0
    split[inside[(inside > 0) & (inside < len(split))]] = True
    segment: IntArray = np.cumsum(split)
    return segment
