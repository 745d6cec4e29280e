"""Why the live heading after an unseen restart's 1 s hold can be 0.21 LSB off, and no less
(issue #11; ``host.judge.livenewstart``, ``host.judge.livefit``).

On the pinned straight 32-bit drive (``tests/test_live_unseen_restart.py``) the live reference's
own heading, against the tests' float64 odometry, is 0.214 heading LSB off from the restart
through the end of the 1 s hold, then goes under 0.05. Asked: bring it under 0.05 LSB at the
hold's end, or explain why it cannot be. It cannot: over the hold the robot drives 1.9 m almost
along X, its HEADING rounds to the same LSB at every sample and its Y takes two values, so the
samples are as consistent with a start heading 0.44 LSB off the true one as with the true one.
This test works that set out itself: for every start heading offset on a 0.001 LSB grid, whether
some start position puts the float64 path (the independent odometry of the drive's counts,
rotated about the restart) within half an LSB of every sample's X, Y and HEADING. The set is
[-0.022, 0.444] LSB; any heading a judge takes can be 0.23 LSB from a correct firmware's, and
the live fit takes its middle (the least worst-case choice). The set narrows to 0.07 LSB once
the Y rounding steps again (1.35 s in): there the live heading ends within 0.05 LSB. A longer
hold would only move the verdict's lag, not this bound, which depends on where the signals'
rounding steps on each drive.
"""

from __future__ import annotations

import math
from pathlib import Path

from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.livenewstart import HOLD_S
from odocan.host.judge.livepose import Sample
from tests.test_live_unseen_restart import DRIVES, _fine_path, _live, _log

GRID_LSB = [i / 1000 for i in range(-1000, 1001)]  # start heading offsets tried (LSB)
Path3 = list[tuple[float, float, float]]


def _consistent(samples: list[Sample], frames: list[int], fine: Path3, offset_lsb: float) -> bool:
    """Whether a correct firmware started ``offset_lsb`` heading LSB off the true heading at
    the first sample (its position free) gives every one of ``samples`` (their rounding)."""
    x0, y0, _ = fine[frames[samples[0].pose.seq]]
    d = offset_lsb * HEADING_LSB_RAD
    cos_d, sin_d = math.cos(d), math.sin(d)
    half_m, half_rad = POSITION_LSB_M / 2, HEADING_LSB_RAD / 2
    lo, hi = [-math.inf, -math.inf], [math.inf, math.inf]
    for sample in samples:
        fx, fy, fh = fine[frames[sample.pose.seq]]
        if abs(math.remainder(sample.pose.heading_rad - fh - d, 2 * math.pi)) > half_rad:
            return False
        qx, qy = fx - x0, fy - y0
        moved = (x0 + cos_d * qx - sin_d * qy, y0 + sin_d * qx + cos_d * qy)
        for axis, (onboard, path) in enumerate(((sample.pose.x_m, moved[0]),
                                                (sample.pose.y_m, moved[1]))):
            lo[axis] = max(lo[axis], onboard - half_m - path)
            hi[axis] = min(hi[axis], onboard + half_m - path)
    return lo[0] <= hi[0] and lo[1] <= hi[1]


def _feasible_lsb(samples: list[Sample], frames: list[int], fine: Path3) -> tuple[float, float]:
    ok = [g for g in GRID_LSB if _consistent(samples, frames, fine, g)]
    return min(ok), max(ok)


def test_the_heading_after_the_hold_is_as_close_as_the_samples_allow(tmp_path: Path) -> None:
    drive = DRIVES["straight32"]
    live = _live(_log(tmp_path, drive), drive)
    fine, frames = _fine_path(drive), live.frames
    life = [s for s in live.samples  # as judged (a sample held settles again once judged)
            if s.reference is not None and drive.restart <= frames[s.pose.seq] < drive.until]
    first_s = life[0].t_s
    held = [s for s in life if s.t_s < first_s + HOLD_S]
    assert len(held) > 45  # the hold's samples (a pose every second frame)
    lo, hi = _feasible_lsb(held, frames, fine)
    assert lo <= 0.0 <= hi  # the drive's own start is among them (a correct firmware)
    assert hi - lo > 0.4, (lo, hi)  # ... and so is one 0.4 LSB off it

    def own_heading_lsb(sample: Sample) -> float:
        assert sample.reference is not None
        heading = fine[frames[sample.reference.seq]][2]
        return math.remainder(sample.reference.heading_rad - heading, 2 * math.pi) / HEADING_LSB_RAD

    judged = [own_heading_lsb(s) for s in held]  # judged at the hold's end by one fit
    assert max(judged) - min(judged) < 1e-6
    assert abs(judged[0] - (lo + hi) / 2) < 0.02, (judged[0], lo, hi)  # its middle
    assert abs(judged[0]) > 0.2  # the 0.21 LSB asked about: half the set, not the judge's error
    lo, hi = _feasible_lsb(life, frames, fine)  # the whole life (to its next hole)
    assert hi - lo < 0.1, (lo, hi)
    assert abs(own_heading_lsb(life[-1])) < 0.05  # the live fit follows the set in
