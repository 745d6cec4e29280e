"""The choice at an evidenceless ambiguous gap by the firmware's next pose
(``host.judge.evidenceless`` module docstring), for the whole log's judge (``analysis``)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from odocan.host.judge.evidenceless import evidenceless
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.reference import Geometry, SpeedBound, integrate, wrap_delta
from odocan.host.judge.reference_path import Steps, firmware_steps
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M, Encoders, Poses


def chosen_seen(enc: Encoders, onboard: Poses, geometry: Geometry, integrator: str, *,
                e0: int, bits: int, max_wheel_speed_mm_s: SpeedBound, seen: Seen) -> Seen:
    """``seen`` with each evidenceless ambiguous gap (from ``e0``) whose next on-board pose the
    gap taken fits better than the re-prime, as proven taken (``Seen.through``: 0)."""
    if not np.any(np.diff(enc.seq[e0:]) > 1):
        return seen  # no gap in the log: nothing to choose (and no second pass over its steps)
    steps = firmware_steps(enc, e0, geometry, bits, max_wheel_speed_mm_s, through=seen.through,
                           resets=seen.resets)
    taken = [e0 + k for k in steps.ambiguous
             if enc.seq[e0 + k] - enc.seq[e0 + k - 1] > 1 and evidenceless(seen, e0 + k)
             and _taken_fits_better(enc, onboard, geometry, integrator, (e0, bits, k), steps)]
    if not taken:
        return seen
    return replace(seen, through={**seen.through, **dict.fromkeys(taken, 0)})


def _taken_fits_better(enc: Encoders, onboard: Poses, geometry: Geometry, integrator: str,
                       at: tuple[int, int, int], steps: Steps) -> bool:
    """Whether the on-board pose after the gap into frame ``e0 + k`` (``at``: e0, the counters'
    bits, k) lies nearer the gap taken than the re-prime (both from the pose before it)."""
    e0, bits, k = at
    before = np.flatnonzero(onboard.enc < e0 + k)
    after = np.flatnonzero(onboard.enc >= e0 + k)
    if not len(before) or not len(after):
        return False  # no pose on one side: the choice judges nothing
    i, j = int(before[-1]), int(after[0])
    a, b = int(onboard.enc[i]) - e0, int(onboard.enc[j]) - e0
    d_left, d_right = steps.d_left[a:b].copy(), steps.d_right[a:b].copy()
    scores = []
    for take in (False, True):
        if take:
            d_left[k - 1 - a] = int(wrap_delta(int(enc.left[e0 + k]) - int(enc.left[e0 + k - 1]),
                                               bits))
            d_right[k - 1 - a] = int(wrap_delta(
                int(enc.right[e0 + k]) - int(enc.right[e0 + k - 1]), bits))
        end = integrate(d_left, d_right, geometry, integrator, x0_m=float(onboard.x_m[i]),
                        y0_m=float(onboard.y_m[i]), heading0_rad=float(onboard.heading_rad[i]))
        off_h = float(onboard.heading_rad[j] - end.heading_rad[-1])
        scores.append(math.hypot(float(onboard.x_m[j] - end.x_m[-1]),
                                 float(onboard.y_m[j] - end.y_m[-1])) / POSITION_LSB_M
                      + abs(off_h) / HEADING_LSB_RAD)
    return scores[1] < scores[0]
