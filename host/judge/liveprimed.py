"""Live, the frame a power-up whose FIFO was drained primed on, among those its count page and
its first pose allow (``host.judge.primedrange``: 0 .. min(k, n), a recorder stamping
ODOM_STATUS late overcounting k).

``analyze`` judges the life from (0, 0, 0) on each of them; the live judges hold one reference,
so they start it on the one whose motion up to the first sample held is the firmware's first
pose (the least error, position in LSBs plus heading in LSBs; ties to the count's own frame).
The correct firmware's first pose is its reference's there, so it is chosen and PASSes; a
firmware off from its first pose is off from every candidate and FAILs from the one it is
nearest (a firmware whose offset is exactly the robot's motion over frames it may have primed
on is one that primed there: ``analyze`` PASSes it too). Where the choice cannot be made (no
sample held yet, or frame 0 has left the window) the reference starts at the first pose, fitted,
and the OK says it was adopted (``liveadopted``): never a silent verdict."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livewindow import Counted, first_named_seq, window_counts
from odocan.host.judge.primedrange import primed_frames
from odocan.host.judge.reference import integrate, wrap_delta
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

UNTOLD_PRIME = ("a power-up primed on one of encoder frames {lo} .. {hi} (its count page and "
                "first pose) not told apart live")


def choose_primed(tracker: PoseTracker, k: int,
                  poses: list[FramePose]) -> tuple[int | None, list[int]]:
    """The frame (seq) to start the first life's reference on at (0, 0, 0), and the frames it
    may have primed on (module docstring); None when not told (then ``UNTOLD_PRIME``)."""
    frames = primed_frames(k, first_named_seq(tracker.pairs.halves["x"], tracker.window))
    counts = window_counts(tracker.window, 0)
    if not counts or counts[0][0] != 0 or not poses:
        return None, frames
    first, at = poses[0], {c[0]: i for i, c in enumerate(counts)}
    tries = [p for p in frames if p in at and p <= first.seq]
    if not tries or first.seq not in at:
        return None, frames
    errors = [_first_error(tracker, counts[at[p]: at[first.seq] + 1], first) for p in tries]
    return tries[int(np.argmin(errors))], frames


def _first_error(tracker: PoseTracker, counts: list[Counted], first: FramePose) -> float:
    """How far (position LSBs plus heading LSBs) the reference from (0, 0, 0) on the first of
    ``counts`` lies, at the last, from the first sample ``first``."""
    assert tracker.integrator is not None
    if len(counts) < 2:
        x_m = y_m = heading_rad = 0.0
    else:
        left = np.array([c[2] for c in counts], dtype=np.int64)
        right = np.array([c[3] for c in counts], dtype=np.int64)
        bits = tracker.counter_bits
        moved = integrate(wrap_delta(np.diff(left), bits), wrap_delta(np.diff(right), bits),
                          tracker.geometry, tracker.integrator)
        x_m, y_m = float(moved.x_m[-1]), float(moved.y_m[-1])
        heading_rad = float(moved.heading_rad[-1])
    turn = math.remainder(first.heading_rad - heading_rad, math.tau)
    return (math.hypot(first.x_m - x_m, first.y_m - y_m) / POSITION_LSB_M
            + abs(turn) / HEADING_LSB_RAD)
