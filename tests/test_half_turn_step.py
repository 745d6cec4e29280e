"""Found trying a 1 cm wheelbase robot live (``odocan sim/firmware/monitor``, the machine loaded):
the monitor and ``analyze`` said POSE WRONG / FAIL (22-27 mm), rightly. A late sim tick makes one
WHEEL_ENCODERS step span 2-3 periods; with a 1 cm wheelbase it turns the robot more than pi, and
the firmware's exact integrator reads the step's heading change as a signed BAM64 (wrapped into
(-pi, pi]): the chord and its direction are then those of the wrapped angle. The heading stays
exact (absolute counts), the position goes mm off, and no error bit says so. Not the judge's
fault: recorded here for the firmware (xfail until it refuses or flags such a step)."""

from __future__ import annotations

import math

import pytest

from odocan.host.judge.reference import ReferenceOdometry
from tests.odo_helpers import firmware, geometry, params

ONE_CM = {"wheelbase_nm": 10_000_000}  # pmir's wheels on a 1 cm wheelbase


@pytest.mark.parametrize(("d_left", "d_right"), [(22, -13), (34, -21)])
@pytest.mark.xfail(strict=True, reason=(
    "firmware/odometry.py: a step turning more than pi is integrated along the wrapped angle "
    "(signed BAM64), silently; a robot spec'd so that one step can turn pi is accepted"))
def test_a_step_turning_more_than_half_a_turn_is_integrated_or_flagged(
    d_left: int, d_right: int
) -> None:
    p = params("exact", **ONE_CM)
    odo, errors = firmware(p)
    ref = ReferenceOdometry(geometry(p), "exact", 16)
    odo.step_deltas(d_left, d_right)
    ref.step_deltas(d_left, d_right)
    assert abs(ref.heading_rad) > math.pi  # more than half a turn in one step
    off_m = math.hypot(odo.x_q40_m / 2**40 - ref.x_m, odo.y_q40_m / 2**40 - ref.y_m)
    assert off_m < 1e-6 or errors.bits != 0
