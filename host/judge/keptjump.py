"""How far a sample lies from a pose moved to it (issue #11, ``host.judge.setposekept``): the
reference's steps from a start pose (a sample, or the power-up pose) to a set-pose's frame, its
staged fields set there, the rest of the steps to the sample after it; the bound is the
roundings the samples carry (and a merged step's allowance, when the caller gives one)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from odocan.host.judge.reference import Geometry, integrate
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M

FLOAT_M = 1e-9  # the firmware's Q40 steps against float64 over a few frames, and more
FLOAT_RAD = 1e-12
TURN_RAD = 2.0 * math.pi


def moved_by(pose: tuple[float, float, float], d_left: np.ndarray, d_right: np.ndarray,
              geometry: Geometry, integrator: str) -> tuple[float, float, float, float]:
    """``pose`` (x m, y m, heading rad) moved by the steps: the pose, and the path (m)."""
    if len(d_left) == 0:
        return (*pose, 0.0)
    moved = integrate(d_left, d_right, geometry, integrator, x0_m=pose[0], y0_m=pose[1],
                      heading0_rad=pose[2])
    return (float(moved.x_m[-1]), float(moved.y_m[-1]), float(moved.heading_rad[-1]),
            float(moved.distance_m[-1]))


def jump_judged(before: tuple[int, tuple[float, float, float]],
                after: tuple[int, tuple[float, float, float]],
                steps: tuple[np.ndarray, np.ndarray], to_cut: int, staged: dict[str, float],
                geometry: Geometry, integrator: str, *, exact_start: bool = False,
                gap_m: float = 0.0) -> dict[str, Any]:
    """The pose ``before`` (encoder frame, pose) moved by the ``to_cut`` steps to the APPLY's
    frame, the staged fields set there, moved by the rest to the sample ``after``: how far that
    sample is. ``exact_start``: ``before`` is the power-up pose, no sample: only ``after``'s
    rounding is left (half an LSB, of position and of heading). ``gap_m``: a merged step's
    bound on the position (``setposekept._gap_m``)."""
    d_left, d_right = steps
    x, y, h, head_m = moved_by(before[1], d_left[:to_cut], d_right[:to_cut], geometry, integrator)
    start = (staged.get("X", x), staged.get("Y", y), staged.get("HEADING", h))
    x, y, h, tail_m = moved_by(start, d_left[to_cut:], d_right[to_cut:], geometry, integrator)
    dx_m, dy_m = after[1][0] - x, after[1][1] - y
    dh_rad = (after[1][2] - h + math.pi) % TURN_RAD - math.pi
    if exact_start:  # the power-up pose: the after sample's rounding alone
        bound_m, bound_rad = 0.5 * POSITION_LSB_M + FLOAT_M, 0.5 * HEADING_LSB_RAD + FLOAT_RAD
    else:  # two samples' roundings, and the start heading's over the path
        bound_m = POSITION_LSB_M + HEADING_LSB_RAD * (head_m + tail_m) + FLOAT_M
        bound_rad = HEADING_LSB_RAD + FLOAT_RAD
    bound_m += gap_m
    passed = max(abs(dx_m), abs(dy_m)) <= bound_m and abs(dh_rad) <= bound_rad
    return {"encoder_frames": after[0] - before[0],
            "position_jump_m": math.hypot(dx_m, dy_m), "heading_jump_rad": abs(dh_rad),
            "bound_m": bound_m, "passed": passed}

