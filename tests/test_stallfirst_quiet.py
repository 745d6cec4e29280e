"""``stallfirst.quiet_times``, the silence before each pose, against its definition per pose.

The rule judging the first pose after a silence reads every ODOM_POSE_X's quiet time at once
(it makes poses only for those after a silence: an hour's ``analyze`` spent 3.6 of its 5.4 s
making every pose). Here each quiet time is computed as the rule used to, pose by pose: seconds
since the X before it (0 for the first), or since the latest pose frame sent strictly before it,
if sooner; the two must be equal to the bit.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from odocan.host.judge.stallfirst import quiet_times

TIMES = st.lists(st.floats(0.0, 100.0, allow_nan=False), max_size=40)


def _one_by_one(tx_s: list[float], sent_s: list[float] | None) -> list[float]:
    quiet = []
    for k, t in enumerate(tx_s):
        since_x = t - tx_s[k - 1] if k else 0.0
        before = [s for s in (sent_s or []) if s < t]
        since_sent = t - before[-1] if before else math.inf
        quiet.append(min(since_x, since_sent) if sent_s else since_x)
    return quiet


@given(TIMES, st.one_of(st.none(), TIMES))
def test_quiet_times_are_the_per_pose_definition(tx: list[float], sent: list[float] | None
                                                 ) -> None:
    tx_s = tx  # bus order: a late frame's time may go back
    sent_s = None if sent is None else sorted(sent)
    got = quiet_times(np.array(tx_s, dtype=np.float64),
                      None if sent_s is None else np.array(sent_s, dtype=np.float64))
    assert got.tolist() == _one_by_one(tx_s, sent_s)


def test_a_silence_of_the_x_frames_narrowed_by_a_pose_sent_in_it() -> None:
    """Poses at 0, 0.01 and 0.5 s; a refused pose frame sent at 0.3 s: 0.2 s quiet, not 0.49."""
    got = quiet_times(np.array([0.0, 0.01, 0.5]), np.array([0.0, 0.01, 0.3]))
    assert got.tolist() == [0.0, 0.01, 0.5 - 0.3]
