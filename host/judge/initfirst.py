"""A firmware's first pose after its INIT summaries is no new life (no pose before: no break).

A firmware that powers up before the motor controller talks says INIT and sends its ODOM_STATUS
(summary, then a rotating page: COUNTER 0, 1 at 0.0 s, ... 14, 15 at 0.7 s) but no pose
(firmware/reports.py) until it primes on an encoder frame. Its first pose, COUNTER 0, then
comes at any phase of its summaries: with the motor controller 740..880 ms late (pmir on the
circle, ``tests/test_init_first_pose.py``), 0..60 ms before or 20..80 ms after its summary of
COUNTER 0 at 0.8 s (UPTIME 0, the status COUNTER's first wrap). ``bootticks.next_run`` and
``bootticks.boot_ahead`` took a pose with no pose before it for one that breaks its sequence,
so that summary was a power-up tick (``boot_tick``; or looked ahead, ``boot_ahead``) and every
judge (``analyze`` whole and streamed, the monitor, the bridge) told a reboot at 0.801 s that
did not happen (issue #11, rule 5; test_trial38's monitor started in the firmware's INIT second).

The rule: a pose with no pose heard before it breaks its message's sequence only when no
ODOM_STATUS frame was heard before it either (the judge heard nothing of the life it might end).
After status frames, the summary's own ``status_breaks`` is the evidence: COUNTER 15 at 0.701 s
then 0 at 0.801 s continues the life; a new firmware's first summary breaks it unless its reset
fell on the old life's own wrap tick (the one reset the two COUNTERs cannot tell: its old life
sent no pose, so the reference starts at the same power-up pose either way; the twists' DISTANCE
falling, ``distfall``, still tells it).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def first_pose_breaks(status_heard: bool) -> bool:
    """Whether a pose with no pose heard before it breaks its sequence (module docstring):
    only when no ODOM_STATUS frame (``status_heard``) was heard before it either."""
    return not status_heard


def status_before_first(status_positions: npt.NDArray[np.int64],
                        pose_positions: npt.NDArray[np.int64], carried: bool) -> bool:
    """Whether an ODOM_STATUS frame whose CRC holds came before the first of ``pose_positions``
    (log positions, in order; ``status_positions`` likewise): in these frames, or before them
    (``carried``: a stream's earlier chunks had one)."""
    if carried:
        return True
    if len(pose_positions) == 0 or len(status_positions) == 0:
        return False
    return bool(status_positions[0] < pose_positions[0])
